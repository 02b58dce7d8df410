"""Saved results read back for a report: a design artifact's manifest (as text, no class
imported), the thresholds it records, and the statistics Parquet of ``fdikit monitor --stats``."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import DataError


def _manifest(path: Path) -> dict | None:
    """The JSON manifest of a design artifact (read as text: no class is imported), or None."""
    p = Path(path)
    js = p if p.suffix == ".json" else p.with_name(p.name + ".json")
    try:
        m = json.loads(js.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return None
    return m if isinstance(m, dict) else None


def _decode(v: Any) -> Any:
    """A manifest payload value as plain Python (lists, dicts, floats); array references -> None."""
    if isinstance(v, dict):
        if "__dict__" in v:
            return {k: _decode(x) for k, x in v["__dict__"].items()}
        for tag in ("__list__", "__tuple__"):
            if tag in v:
                return [_decode(x) for x in v[tag]]
        if "__float__" in v:
            return float(v["__float__"])
        return None
    return v


def _manifest_thresholds(man: dict | None) -> dict[str, tuple[float, bool]]:
    """Thresholds of a threshold-rule artifact (payload ``inputs`` and ``threshold``, as
    :class:`fdikit.detect.Hold` saves them), read from its manifest."""
    pay = _decode((man or {}).get("payload"))
    if not isinstance(pay, dict) or not isinstance(pay.get("inputs"), list) or "threshold" not in pay:
        return {}
    names, thr = pay["inputs"], pay["threshold"]
    try:
        vals = np.broadcast_to(np.asarray(thr, float), (len(names),))
    except (TypeError, ValueError):
        return {}  # stored in the NPZ, or not a plain rule: no line drawn
    return {
        str(n): (float(v), bool(pay.get("absolute", False))) for n, v in zip(names, vals) if np.isfinite(v)
    }


def _read_stats(path: Path) -> tuple[np.ndarray, dict[str, np.ndarray], np.ndarray | None]:
    import pyarrow.parquet as pq

    if not path.is_file():
        raise DataError(f"{path}: no such statistics file")
    try:
        table = pq.read_table(path)
    except Exception as exc:
        raise DataError(f"{path}: not a readable Parquet file ({type(exc).__name__}: {exc})") from None
    cols = table.column_names
    if "t" not in cols:
        raise DataError(f"{path}: the statistics table has no time column 't'; columns: {cols[:12]}")
    t = np.asarray(table.column("t").to_numpy(), float)
    valid = np.asarray(table.column("valid").to_numpy(), bool) if "valid" in cols else None
    out = {}
    for c in cols:
        if c in ("t", "valid"):
            continue
        try:
            out[c] = np.asarray(table.column(c).to_numpy(zero_copy_only=False), float)
        except (TypeError, ValueError) as exc:
            raise DataError(f"{path}: column {c!r} is not numeric ({exc})") from None
    return t, out, valid
