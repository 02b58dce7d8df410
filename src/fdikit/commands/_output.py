"""JSON output of every command: exactly one object on stdout, NaN and inf as null."""

from __future__ import annotations

import json
import sys
from typing import Any

import numpy as np

__all__ = ["print_json"]


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
