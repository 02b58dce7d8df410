"""Runtime state of streaming components: capture, restore, and an atomic checkpoint file.

Every streaming component (residual generator or processor) lists the attributes that hold its
state between samples in ``_state_attrs``; :class:`Stateful` captures them with
:meth:`~Stateful.get_state` (deep copies: arrays, numbers, tuples, dicts, and nested stateful
components) and puts them back with :meth:`~Stateful.set_state`. A state is plain data, so it
is saved without pickle: :func:`save_state` writes one ``.npz`` file whose arrays are the
state's arrays and whose ``__manifest__`` entry is JSON describing the structure and the
scalars. The file is written to a temporary name in the same directory and renamed over the
target (``os.replace``), so a crash mid-write never leaves a corrupt checkpoint.
"""

from __future__ import annotations

import copy
import json
import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import DataError

__all__ = ["STATE_FORMAT", "Stateful", "load_state", "save_state"]

#: Version of the checkpoint file layout.
STATE_FORMAT = "fdikit-state/1"


class Stateful:
    """Mixin: ``get_state()`` / ``set_state(state)`` over the attributes in ``_state_attrs``."""

    _state_attrs: tuple[str, ...] = ()

    def get_state(self) -> dict[str, Any]:
        """A deep copy of the component's streaming state (plain data)."""
        out = {}
        for name in self._state_attrs:
            out[name] = _capture(getattr(self, name, None))
        return out

    def set_state(self, state: dict[str, Any]) -> None:
        """Restore a state captured by :meth:`get_state` on an identically configured component."""
        if not isinstance(state, dict):
            raise DataError(f"{type(self).__name__}: a state must be a dict, got {type(state).__name__}")
        want, got = set(self._state_attrs), set(state)
        if want != got:
            raise DataError(f"{type(self).__name__}: state has keys {sorted(got)}, expected {sorted(want)}")
        for name in self._state_attrs:
            cur = getattr(self, name, None)
            setattr(self, name, _restore(cur, state[name], f"{type(self).__name__}.{name}"))


def _capture(v: Any) -> Any:
    if isinstance(v, Stateful):
        return {"__component__": v.get_state()}
    if isinstance(v, list | tuple) and any(isinstance(x, Stateful) for x in v):
        return {"__components__": [_capture(x) for x in v]}
    return copy.deepcopy(v)


def _restore(cur: Any, v: Any, where: str) -> Any:
    if isinstance(v, dict) and "__component__" in v:
        if not isinstance(cur, Stateful):
            raise DataError(f"{where}: state holds a component but the target has {type(cur).__name__}")
        cur.set_state(v["__component__"])
        return cur
    if isinstance(v, dict) and "__components__" in v:
        items = v["__components__"]
        if not isinstance(cur, list | tuple) or len(cur) != len(items):
            raise DataError(f"{where}: state holds {len(items)} components, the target does not match")
        for c, s in zip(cur, items):
            _restore(c, s, where)
        return cur
    if isinstance(cur, np.ndarray) and isinstance(v, np.ndarray) and cur.dtype != v.dtype:
        raise DataError(f"{where}: dtype {v.dtype} in the state, {cur.dtype} expected")
    return copy.deepcopy(v)


# ------------------------------------------------------------------------------------ file form
def _flatten(v: Any, key: str, arrays: dict[str, np.ndarray]) -> Any:
    """Structure description (JSON-able) of ``v``; arrays go to ``arrays`` under ``key``."""
    if isinstance(v, np.ndarray):
        if v.dtype == object:
            raise DataError(f"state entry {key!r} is an object array; only numeric arrays can be saved")
        arrays[key] = v
        return {"__array__": key}
    if isinstance(v, dict):
        for k in v:
            if not isinstance(k, str):
                raise DataError(f"state entry {key!r} has a non-string key {k!r}")
        return {"__dict__": {k: _flatten(x, f"{key}/{k}", arrays) for k, x in v.items()}}
    if isinstance(v, tuple):
        return {"__tuple__": [_flatten(x, f"{key}/{i}", arrays) for i, x in enumerate(v)]}
    if isinstance(v, list):
        return {"__list__": [_flatten(x, f"{key}/{i}", arrays) for i, x in enumerate(v)]}
    if isinstance(v, np.generic):
        return {"__scalar__": v.item(), "dtype": str(v.dtype)}
    if v is None or isinstance(v, bool | int | str):
        return v
    if isinstance(v, float):
        return {"__float__": repr(v)}  # repr round-trips exactly, including inf and nan
    raise DataError(f"state entry {key!r} has type {type(v).__name__}, which cannot be saved")


def _unflatten(d: Any, arrays: dict[str, np.ndarray]) -> Any:
    if isinstance(d, dict):
        if "__array__" in d:
            return arrays[d["__array__"]].copy()
        if "__dict__" in d:
            return {k: _unflatten(x, arrays) for k, x in d["__dict__"].items()}
        if "__tuple__" in d:
            return tuple(_unflatten(x, arrays) for x in d["__tuple__"])
        if "__list__" in d:
            return [_unflatten(x, arrays) for x in d["__list__"]]
        if "__scalar__" in d:
            return np.dtype(d["dtype"]).type(d["__scalar__"])
        if "__float__" in d:
            return float(d["__float__"])
        raise DataError(f"unknown entry in a state manifest: {sorted(d)}")
    return d


def _umask() -> int:
    """The process's umask: from ``/proc/self/status`` where Linux gives it (thread-safe), else
    read by setting and restoring it."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _atomic_write(path: Path, write, *, mkdir: bool = False) -> None:
    """Write a file through ``write(fh)`` atomically: a temporary file beside it, fsync, rename
    (a crash mid-write never leaves a corrupt file; shared by checkpoints and artifacts).

    The file gets the permissions of any file the process creates (``0o666`` less the umask),
    not the ``0o600`` of a temporary file. A missing folder is created with ``mkdir=True`` and
    is otherwise a :class:`DataError` naming it, as is a folder that cannot be written.
    """
    path = Path(path)
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        if parent.exists():
            raise DataError(f"{path}: cannot write there, {str(parent)!r} is a file, not a folder")
        if not mkdir:
            raise DataError(f"{path}: cannot write there, the folder {str(parent)!r} does not exist")
        try:
            parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise DataError(f"{path}: cannot create the folder {str(parent)!r} ({exc.strerror or exc})"
                            ) from None
    try:
        fd, tmp = tempfile.mkstemp(prefix=path.name + ".", suffix=".tmp", dir=parent)
    except OSError as exc:
        raise DataError(f"{path}: cannot write into the folder {str(parent)!r} ({exc.strerror or exc})"
                        ) from None
    try:
        os.fchmod(fd, 0o666 & ~_umask())
        with os.fdopen(fd, "wb") as fh:
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def save_state(path: str | os.PathLike, state: Any, *, meta: dict | None = None) -> Path:
    """Write ``state`` to ``path`` (``.npz``) atomically; ``meta`` is stored beside it (JSON).

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> p = os.path.join(tempfile.mkdtemp(), "ck.npz")
    >>> _ = save_state(p, {"x": np.arange(3.0), "k": 7, "t": 0.1})
    >>> s, meta = load_state(p)
    >>> s["x"].tolist(), s["k"], s["t"]
    ([0.0, 1.0, 2.0], 7, 0.1)
    """
    path = Path(path)
    arrays: dict[str, np.ndarray] = {}
    manifest = {"format": STATE_FORMAT, "state": _flatten(state, "s", arrays), "meta": meta or {}}
    payload = {f"a{i}": a for i, a in enumerate(arrays.values())}
    names = dict(zip(arrays, payload))
    manifest["arrays"] = names
    payload["__manifest__"] = np.array(json.dumps(manifest))
    _atomic_write(path, lambda fh: np.savez(fh, **payload))
    return path


def load_state(path: str | os.PathLike) -> tuple[Any, dict]:
    """Read a checkpoint written by :func:`save_state`: returns ``(state, meta)``."""
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as z:
            manifest = json.loads(str(z["__manifest__"]))
            arrays = {key: z[stored] for key, stored in manifest["arrays"].items()}
    except (OSError, ValueError, KeyError, json.JSONDecodeError) as exc:
        raise DataError(f"{path}: not a readable fdikit checkpoint ({exc})") from None
    if manifest.get("format") != STATE_FORMAT:
        raise DataError(f"{path}: checkpoint format {manifest.get('format')!r}, expected {STATE_FORMAT!r}")
    return _unflatten(manifest["state"], arrays), manifest.get("meta", {})
