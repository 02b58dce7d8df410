"""Paths written in a config file: ``~`` and environment variables expanded, relative to the file.

A config names files and folders (``[monitor].artifacts``, ``[log].dbc``, ``[design.plant].file``,
``[design.noise].nominal_log``). A user writes them as a shell would: ``~/designs``,
``$HOME/logs/x.csv``, ``${DATA}/car.dbc``. :func:`config_path` expands them the same way and
resolves a relative result against the config's folder, so a config means the same thing from
whatever folder it is run. An environment variable that is not set is refused by name rather
than kept as a literal folder named ``$DATA``.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

from ..errors import DataError

__all__ = ["config_path"]

_VAR = re.compile(r"\$(\w+|\{[^}]*\})")


def config_path(base: str | os.PathLike | None, value: str | os.PathLike, *, where: str = "config") -> Path:
    """The absolute path a config entry names.

    Parameters
    ----------
    base : path or None
        The folder of the config file (relative entries are relative to it); None: the current
        folder.
    value : str or path
        The entry as written: may start with ``~`` or ``~user`` and hold ``$VAR`` / ``${VAR}``.
    where : str
        The entry's place in the config, for the error message (``"[monitor].artifacts"``).

    Returns
    -------
    pathlib.Path
        Expanded and resolved (absolute).

    Raises
    ------
    DataError
        An environment variable in the entry is not set, or ``~user`` names no user.

    Examples
    --------
    >>> import os
    >>> os.environ["FDIKIT_DOC_DIR"] = "/data"
    >>> str(config_path("/cfg", "${FDIKIT_DOC_DIR}/logs"))
    '/data/logs'
    >>> str(config_path("/cfg", "designs"))
    '/cfg/designs'
    >>> config_path("/cfg", "$FDIKIT_NOT_SET_X/a", where="[log].dbc")   # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    fdikit.errors.DataError: [log].dbc = '$FDIKIT_NOT_SET_X/a': the environment variable ... is not set
    """
    text = os.fspath(value)
    for m in _VAR.finditer(text):
        name = m.group(1).strip("{}")
        if name not in os.environ:
            raise DataError(f"{where} = {text!r}: the environment variable {name} is not set")
    expanded = os.path.expanduser(os.path.expandvars(text))
    if expanded.startswith("~"):
        raise DataError(f"{where} = {text!r}: {expanded.split(os.sep)[0]!r} names no user's home folder")
    p = Path(expanded)
    if not p.is_absolute():
        p = Path(base if base is not None else ".") / p
    return p.resolve()
