"""Decisions from binary test outcomes: maximum likelihood over learned test reliabilities, and
walking a diagnostic tree (luo-et-al, Section VII)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import DataError

__all__ = ["Diagnosis", "diagnose_likelihood", "diagnose_ml", "diagnose_tree"]


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


@dataclass
class Diagnosis:
    """Maximum-likelihood (or maximum-posterior) diagnoses of many outcome vectors.

    Attributes
    ----------
    classes : list of str
        Candidate classes (the rows of the D-matrix or signature, nominal class included).
    index : ndarray of int (runs,)
        Index of the diagnosed class (first of the ambiguity set).
    loglik : ndarray (runs, n_classes)
        ``log P(outcomes | class)`` (natural log), plus ``log prior`` when a prior was given.
    posterior : ndarray (runs, n_classes)
        Normalised ``exp(loglik)`` (the posterior under the prior, uniform by default).
    ambiguity : list of tuple of str
        Per run, every class whose score ties the best within ``tol`` (the ambiguity set; one class
        when the outcomes isolate it).
    """

    classes: list[str]
    index: np.ndarray
    loglik: np.ndarray
    posterior: np.ndarray
    ambiguity: list[tuple[str, ...]]

    @property
    def best(self) -> list[str]:
        """The diagnosed class of every run."""
        return [self.classes[i] for i in self.index]

    @property
    def isolated(self) -> np.ndarray:
        """True where the ambiguity set has one class, (runs,)."""
        return np.array([len(a) == 1 for a in self.ambiguity], bool)

    def __len__(self) -> int:
        return len(self.index)


def diagnose_likelihood(fired: np.ndarray, fail_prob: np.ndarray, classes: Sequence[str], *,
                        prior=None, tol: float = 1e-9, floor: float = 1e-6) -> Diagnosis:
    """Maximum likelihood (or maximum posterior with ``prior``) over every class, with ambiguity sets.

    ``log P(o | i) = sum_j o_j log q_ij + (1 - o_j) log(1 - q_ij)`` with ``q_ij`` the probability that
    test ``j`` fires under class ``i`` (clipped to ``[floor, 1 - floor]``; tests conditionally
    independent given the class). Unlike :func:`diagnose_ml` no class is special: the nominal class
    competes on its false-alarm probabilities like any other.

    Parameters
    ----------
    fired : bool array (runs, n_tests) or (n_tests,)
    fail_prob : array (n_classes, n_tests)
    classes : sequence of str
    prior : array_like (n_classes,), optional
        Class probabilities (any positive scale); default uniform.
    tol : float
        Classes whose score is within ``tol`` of the best form the ambiguity set.
    floor : float
        Clip of the probabilities (a perfect test that contradicts a class gives ``log(floor)``).

    Returns
    -------
    Diagnosis

    Examples
    --------
    >>> import numpy as np
    >>> q = np.array([[0.01, 0.01], [0.99, 0.01], [0.99, 0.01]])
    >>> d = diagnose_likelihood(np.array([[0, 0], [1, 0]], bool), q, ["F0", "A", "B"])
    >>> d.best, d.ambiguity
    (['F0', 'A'], [('F0',), ('A', 'B')])
    """
    o = np.asarray(fired, float)
    if o.ndim == 1:
        o = o[None]
    p = np.clip(np.asarray(fail_prob, float), floor, 1 - floor)
    classes = list(classes)
    if o.ndim != 2 or p.ndim != 2 or o.shape[1] != p.shape[1] or p.shape[0] != len(classes):
        raise DataError(f"outcomes {o.shape} and reliabilities {p.shape} do not match {len(classes)} classes")
    bad = ~np.isfinite(o) | ((o != 0) & (o != 1))
    if np.any(bad):
        r, j = map(int, np.argwhere(bad)[0])
        raise DataError(f"outcome of run {r}, test {j} is {o[r, j]!r}; outcomes are 0/1 (True = fired)")
    ll = o @ np.log(p).T + (1 - o) @ np.log1p(-p).T
    if prior is not None:
        pr = np.asarray(prior, float).ravel()
        if pr.shape != (len(classes),) or np.any(~np.isfinite(pr)) or np.any(pr < 0) or pr.sum() <= 0:
            raise DataError(f"prior must be {len(classes)} non-negative numbers, got {np.shape(prior)}")
        with np.errstate(divide="ignore"):
            ll = ll + np.log(pr / pr.sum())
    top = ll.max(axis=1, keepdims=True)
    w = np.exp(ll - top)
    post = w / w.sum(axis=1, keepdims=True)
    tie = ll >= top - tol
    idx = np.argmax(tie, axis=1)
    amb = [tuple(classes[i] for i in np.flatnonzero(row)) for row in tie]
    return Diagnosis(classes, idx, ll, post, amb)
