"""Output of every command: exactly one JSON object on stdout (NaN and inf as null), and the output
paths a command will write checked before any computation (:func:`check_output_paths`: writable,
never an input, never another output's file)."""

from __future__ import annotations

import json
import os
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from ..base.outputs import check_outputs
from ..errors import DataError

__all__ = ["IMAGE_SUFFIXES", "OUTPUT_SUFFIXES", "check_output_paths", "print_json"]

#: File endings matplotlib writes (``--plot``).
IMAGE_SUFFIXES = (".png", ".pdf", ".svg", ".jpg", ".jpeg", ".eps", ".ps", ".tif", ".tiff", ".webp")

#: Required endings of the usual output options (an option not listed takes any name).
OUTPUT_SUFFIXES: dict[str, tuple[str, ...]] = {"report": (".html", ".htm"), "plot": IMAGE_SUFFIXES}


def _to_jsonable(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {str(k): _to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _to_jsonable(obj.tolist())
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.floating | float):
        f = float(obj)
        return f if np.isfinite(f) else None
    return obj


def print_json(obj: Any) -> None:
    """Print exactly one JSON object on stdout (NaN/inf become null)."""
    sys.stdout.write(json.dumps(_to_jsonable(obj), allow_nan=False) + "\n")
    sys.stdout.flush()


def _writable_folder(folder: Path, what: str) -> None:
    """Raise unless a file can really be created in ``folder`` (tried: permission bits say nothing
    to root, and a read-only file system says nothing to ``os.access``)."""
    try:
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as exc:
        raise DataError(f"{what}: cannot write into the folder {str(folder)!r} ({exc.strerror or exc})"
                        ) from None


def check_output_paths(args: Any, *options: str, folders: tuple[str, ...] = (),
                       suffixes: dict[str, tuple[str, ...]] | None = None,
                       labels: dict[str, str] | None = None, inputs: tuple[str, ...] = ()) -> None:
    """Check the output paths a command was given, before any computation.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line; an option that is absent or ``None``/empty is skipped.
    *options : str
        Attribute names of file outputs (``"events"``, ``"stats"``, ``"plot"``, ``"report"``,
        ``"checkpoint"``, ...): the folder must exist and be writable, the path must not be a
        folder, an existing file must be writable, and the ending must be one of
        ``suffixes[option]`` (default :data:`OUTPUT_SUFFIXES`) where one is required.
    folders : tuple of str
        Attribute names of output folders that the command creates (``--out``): the folder may be
        missing, but its nearest existing parent must be a writable folder, and it must not be a
        file.
    suffixes : dict, optional
        Overrides of :data:`OUTPUT_SUFFIXES` per option.
    labels : dict, optional
        How messages name an option (default ``--name``; e.g. ``{"out": "OUT"}`` for a positional).
    inputs : tuple of str
        Attribute names of the files the command reads (``"log"``, ``"config"``): no output may
        be one of them, and no two outputs may be the same file
        (:func:`fdikit.base.outputs.check_outputs`).

    Raises
    ------
    DataError
        Naming the option, the path and what is wrong.

    Examples
    --------
    >>> import argparse
    >>> check_output_paths(argparse.Namespace(events=None, stats=None), "events", "stats")
    >>> check_output_paths(argparse.Namespace(events="/no/such/folder/ev.jsonl"), "events")
    Traceback (most recent call last):
    ...
    fdikit.errors.DataError: --events /no/such/folder/ev.jsonl: the folder '/no/such/folder' does not exist
    """
    want = {**OUTPUT_SUFFIXES, **(suffixes or {})}

    def label(name: str) -> str:
        return (labels or {}).get(name, f"--{name.replace('_', '-')}")

    def given(names) -> dict:
        return {label(n): v for n in names
                if isinstance(v := getattr(args, n, None), str | os.PathLike) and v}

    check_outputs(given(options), given(inputs))

    for name in options:
        value = getattr(args, name, None)
        if not value or not isinstance(value, str | os.PathLike):
            continue
        p = Path(value)
        what = f"{label(name)} {p}"
        ends = want.get(name, ())
        if ends and p.suffix.lower() not in ends:
            raise DataError(f"{what}: the file must end in {' or '.join(ends)}")
        parent = p.parent if str(p.parent) else Path(".")
        if not parent.exists():
            raise DataError(f"{what}: the folder {str(parent)!r} does not exist")
        if not parent.is_dir():
            raise DataError(f"{what}: {str(parent)!r} is a file, not a folder")
        if p.is_dir():
            raise DataError(f"{what}: is a folder, not a file")
        if p.exists() and not os.access(p, os.W_OK):
            raise DataError(f"{what}: the file exists and cannot be written (permission denied)")
        _writable_folder(parent, what)
    for name in folders:
        value = getattr(args, name, None)
        if not value:
            continue
        p = Path(value)
        what = f"{label(name)} {p}"
        if p.exists() and not p.is_dir():
            raise DataError(f"{what}: is a file, not a folder")
        q = p
        while not q.exists():
            q = q.parent if str(q.parent) else Path(".")
            if q == q.parent and not q.exists():
                break
        if not q.is_dir():
            raise DataError(f"{what}: {str(q)!r} is a file, not a folder")
        _writable_folder(q, what)
