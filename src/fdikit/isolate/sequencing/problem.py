"""The test-sequencing problem as given: priors of the fault states, test costs and the test model
(perfect or unreliable), checked against the D-matrix."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ...errors import DataError
from ..dmatrix import DMatrix

_HEURISTICS = {"perfect": ("huffman", "entropy", "mincost", "zero"),
               "unreliable": ("bayes", "mincost", "zero")}


def _named_vector(values, names: list[str], what: str, per: str, owner: str) -> np.ndarray:
    """A finite, non-negative vector with one entry per name, from a mapping or a sequence."""
    if isinstance(values, Mapping):
        unknown = [k for k in values if k not in names]
        if unknown:
            raise DataError(f"{what} names {unknown} are not {per}s of the D-matrix {names}")
        missing = [f for f in names if f not in values]
        if missing:
            raise DataError(f"{what} has no {'probability' if what == 'prior' else 'value'} for {per}s "
                            f"{missing}")
        v = np.array([float(values[f]) for f in names])
    else:
        v = np.asarray(values, float).ravel()
        if v.shape != (len(names),):
            raise DataError(f"{what} has {v.size} entries but the D-matrix has {len(names)} {per}s {names}")
    bad = ~np.isfinite(v) | (v < 0)
    if np.any(bad):
        i = int(np.argmax(bad))
        raise DataError(f"{what} of {per} {names[i]!r} is {v[i]}; {owner} must be finite and >= 0")
    return v


def _check_prior(dm: DMatrix, prior) -> np.ndarray:
    if prior is None:
        return np.full(len(dm.faults), 1.0 / len(dm.faults))
    p = _named_vector(prior, list(dm.faults), "prior", "fault", "priors")
    s = float(p.sum())
    if abs(s - 1.0) > 1e-9:
        raise DataError(f"prior probabilities sum to {s:.12g}, not 1 (single-fault assumption: the fault "
                        "states, including the no-fault state if modelled, are exhaustive and exclusive)")
    return p


def _check_cost(dm: DMatrix, cost) -> np.ndarray:
    if cost is None:
        return np.ones(len(dm.tests))
    return _named_vector(cost, list(dm.tests), "cost", "test", "test costs")


def _mode(dm: DMatrix, tests_model: str, misdiagnosis_cost) -> tuple[str, float | None]:
    if tests_model == "auto":
        tests_model = "perfect" if dm.is_perfect else "unreliable"
    if tests_model not in ("perfect", "unreliable"):
        raise DataError(f"tests_model must be 'auto', 'perfect' or 'unreliable', got {tests_model!r}")
    if tests_model == "unreliable":
        if misdiagnosis_cost is None:
            raise DataError("unreliable-test sequencing needs misdiagnosis_cost (the cost of declaring the "
                            "wrong fault, in test-cost units); the D-matrix has Pd < 1 or Pf > 0 entries")
        M = float(misdiagnosis_cost)
        if not np.isfinite(M) or M < 0:
            raise DataError(f"misdiagnosis_cost must be finite and >= 0, got {misdiagnosis_cost}")
        return tests_model, M
    return tests_model, None
