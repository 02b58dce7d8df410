"""Argument validation of the SMO modules: finite matrices of a stated shape and positive
parameters, or a :class:`~fdikit.errors.DataError` naming them."""

from __future__ import annotations

from typing import Any

import numpy as np

from ...errors import DataError


def _mat(X: Any, shape: tuple[int | None, int | None], what: str) -> np.ndarray:
    """``X`` as a finite 2-D float array of ``shape`` (``None``: any size), or DataError naming it.

    A 1-D array is a column when the row count is fixed (``(n,)`` -> ``(n, 1)``); nothing is
    reshaped otherwise, so a transposed matrix is refused, never silently reshaped.
    """
    a = np.asarray(X, dtype=float)
    if a.ndim == 1 and shape[0] is not None and a.size == shape[0] and shape[1] in (None, 1):
        a = a.reshape(-1, 1)
    elif a.ndim == 0 and shape == (1, 1):
        a = a.reshape(1, 1)
    if a.ndim == 1 and a.size == 0 and shape[0] is not None:
        a = a.reshape(shape[0], 0)
    if a.ndim != 2:
        raise DataError(f"{what} must be a 2-D matrix of shape {_shape_text(shape)}, got shape {a.shape}")
    for i, want in enumerate(shape):
        if want is not None and a.shape[i] != want:
            hint = " (transposed?)" if None not in shape and a.shape == shape[::-1] else ""
            raise DataError(f"{what} must have shape {_shape_text(shape)}, got {a.shape}{hint}")
    if not np.all(np.isfinite(a)):
        bad = tuple(int(i) for i in np.argwhere(~np.isfinite(a))[0])
        raise DataError(f"{what} contains a non-finite value at {bad}")
    return a


def _shape_text(shape) -> str:
    return "(" + ", ".join("any" if s is None else str(s) for s in shape) + ")"


def _pos(x: Any, what: str, *, allow_zero: bool = False) -> float:
    """A finite positive float (or >= 0 with ``allow_zero``), or DataError naming the parameter."""
    try:
        v = float(x)
    except (TypeError, ValueError):
        raise DataError(f"{what} must be a number, got {x!r}") from None
    if not np.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        raise DataError(f"{what} must be finite and {'>= 0' if allow_zero else '> 0'}, got {x!r}")
    return v


def _norm2(X: np.ndarray) -> float:
    return float(np.linalg.norm(X, 2)) if X.size else 0.0


def _spd(X: np.ndarray, what: str) -> np.ndarray:
    """``X`` if symmetric positive definite, or DataError naming it with its smallest eigenvalue."""
    if X.size == 0:
        return X
    asym = float(np.abs(X - X.T).max())
    if asym > 1e-10 * max(float(np.abs(X).max()), 1e-300):
        raise DataError(f"{what} must be symmetric positive definite; it is not symmetric "
                        f"(largest |X - X^T| = {asym:.3g})")
    lam = float(np.linalg.eigvalsh(0.5 * (X + X.T)).min())
    if not lam > 0:
        raise DataError(f"{what} must be symmetric positive definite; its smallest eigenvalue is "
                        f"{lam:.4g}")
    return X
