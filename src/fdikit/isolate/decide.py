"""Decisions from binary test outcomes: maximum likelihood over learned test reliabilities, and
walking a diagnostic tree (luo-et-al, Section VII)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..errors import DataError

__all__ = ["diagnose_ml", "diagnose_tree"]


def diagnose_ml(fired: np.ndarray, fail_prob: np.ndarray, classes: Sequence[str], *,
                nominal: str | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Diagnosis from binary test outcomes: "system OK" when every test passes, else the most likely fault.

    With a ``nominal`` class, a run in which no test fired is diagnosed ``nominal`` (the Go path
    of a diagnostic tree, luo-et-al Section VII). Otherwise the diagnosis is the fault class
    (``nominal`` excluded) of maximum likelihood
    ``log P(o | i) = sum_j o_j log p_ij + (1 - o_j) log(1 - p_ij)``, with ``p_ij`` the
    probability that test ``j`` fires under class ``i`` (clipped to [1e-6, 1 - 1e-6]) and equal
    priors. (Without the Go-path rule, an undetectable fault whose learned firing
    probabilities are a hair below the nominal false-alarm rates would win every all-pass run.)

    Parameters
    ----------
    fired : bool array (runs, n_tests)
    fail_prob : array (n_classes, n_tests)
    classes : sequence of str
    nominal : str or None
        The no-fault class (e.g. ``"F0"``); None (default): plain maximum likelihood over every
        class.

    Returns
    -------
    best : ndarray of int (runs,)
        Index of the diagnosed class (first on ties).
    tie : ndarray of bool (runs, n_classes)
        Candidate classes whose likelihood equals the best (to 1e-9); only ``nominal`` for
        all-pass runs.

    Examples
    --------
    >>> import numpy as np
    >>> p = np.array([[0.01, 0.01], [0.99, 0.01], [0.99, 0.99]])
    >>> best, _ = diagnose_ml(np.array([[0, 0], [1, 0], [1, 1], [0, 1]], bool), p, ["F0", "A", "B"],
    ...                       nominal="F0")
    >>> best.tolist()
    [0, 1, 2, 2]
    """
    o = np.asarray(fired, float)
    p = np.clip(np.asarray(fail_prob, float), 1e-6, 1 - 1e-6)
    classes = list(classes)
    if o.ndim != 2 or p.ndim != 2 or o.shape[1] != p.shape[1] or p.shape[0] != len(classes):
        raise DataError(f"outcomes {o.shape} and reliabilities {p.shape} do not match {len(classes)} classes")
    ll = o @ np.log(p).T + (1 - o) @ np.log1p(-p).T
    if nominal is not None:
        if nominal not in classes:
            raise DataError(f"nominal class {nominal!r} not among {classes}")
        i0 = classes.index(nominal)
        ll[:, i0] = -np.inf
        ok = ~o.any(axis=1)
    best = ll.argmax(axis=1)
    tie = ll >= ll.max(axis=1, keepdims=True) - 1e-9
    if nominal is not None:
        best[ok] = i0
        tie[ok] = False
        tie[ok, i0] = True
    return best, tie


def diagnose_tree(fired: np.ndarray, tree, tests: Sequence[str]) -> list[tuple[str, ...]]:
    """Walk each run's test outcomes down a diagnostic tree (:func:`fdikit.isolate.ao_star`).

    Parameters
    ----------
    fired : bool array (runs, n_tests)
        Outcomes in the order of ``tests`` (True = the test fired, "NG").
    tree : DiagnosticTree
    tests : sequence of str

    Returns
    -------
    list of tuple of str
        The leaf group reached by each run (only the tests on its path are read).

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit.isolate import DMatrix, ao_star
    >>> tree = ao_star(DMatrix(["F0", "F1", "F2"], ["t1", "t2"], [[0, 0], [1, 0], [1, 1]]))
    >>> diagnose_tree(np.array([[0, 0], [1, 1], [0, 1]], bool), tree, ["t1", "t2"])
    [('F0',), ('F2',), ('F0',)]
    """
    tests = list(tests)
    fired = np.asarray(fired, bool)
    if fired.ndim != 2 or fired.shape[1] != len(tests):
        raise DataError(f"outcomes of shape {fired.shape} do not match the tests {tests}")
    cache: dict[bytes, tuple[str, ...]] = {}
    out = []
    for row in fired:
        key = row.tobytes()
        if key not in cache:
            cache[key] = tree.diagnose(dict(zip(tests, row.tolist())))
        out.append(cache[key])
    return out
