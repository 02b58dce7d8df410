"""The diagnostic matrix (D-matrix) of a test design, optionally with test reliabilities.

A D-matrix ``D = {d_ij}`` has one row per fault state (including, if the user wants it, the
no-fault state ``"F0"``) and one column per test; ``d_ij = 1`` when test ``j`` detects fault
state ``i`` (luo-et-al, Section VII and Table IV). Rows that are identical cannot be told
apart by any test: they form an *ambiguity group*. This module reports such groups; it never
merges them silently.

Unreliable tests carry, for each (fault, test) pair, a detection probability ``Pd_ij`` (used where
``d_ij = 1``) and a false-alarm probability ``Pf_ij`` (used where ``d_ij = 0``); the pair is the
``P_ij = (Pd_ij, Pf_ij)`` of the bipartite digraph of luo-et-al, Fig. 13. The probability that
test ``j`` *fails* (fires, outcome NG) under fault ``i`` is then ``Pd_ij`` if ``d_ij = 1`` and
``Pf_ij`` otherwise (:meth:`DMatrix.fail_probability`).

Outcome convention used throughout :mod:`fdikit.isolate`: ``True`` / ``1`` = the test fails
(fires, "NG"), ``False`` / ``0`` = the test passes ("G").
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from ..errors import DataError, ModelError

__all__ = ["DMatrix", "wilson_interval"]


def wilson_interval(k, n, confidence: float = 0.95):
    """Wilson score confidence interval of a binomial proportion ``k / n``.

    Parameters
    ----------
    k : int or array_like of int
        Number of successes (e.g. runs in which a test fired).
    n : int or array_like of int
        Number of trials (runs), ``>= 1``; broadcast against ``k``.
    confidence : float
        Two-sided confidence level in (0, 1).

    Returns
    -------
    lo, hi : ndarray
        Lower and upper bounds, shape of ``broadcast(k, n)``, within [0, 1].

    Notes
    -----
    ``(p + z^2/(2n) +- z sqrt(p(1-p)/n + z^2/(4n^2))) / (1 + z^2/n)`` with ``p = k/n`` and ``z`` the
    standard-normal quantile of ``(1 + confidence)/2`` (Wilson 1927). Unlike the Wald interval it
    stays inside [0, 1] and is not degenerate at ``k = 0`` or ``k = n``, which matters for Pf
    estimated from runs with no false alarm.

    Examples
    --------
    >>> lo, hi = wilson_interval(0, 5000)
    >>> float(lo), round(float(hi), 6)
    (0.0, 0.000768)
    """
    from scipy.stats import norm

    k = np.asarray(k, float)
    n = np.asarray(n, float)
    if not 0.0 < confidence < 1.0:
        raise DataError(f"confidence must lie in (0, 1), got {confidence}")
    if np.any(n < 1):
        raise DataError(f"the number of trials must be >= 1, got min {n.min()}")
    if np.any(k < 0) or np.any(k > n):
        raise DataError("the number of successes must lie in [0, n]")
    z = norm.ppf(0.5 * (1.0 + confidence))
    p = k / n
    den = 1.0 + z * z / n
    mid = (p + z * z / (2 * n)) / den
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / den
    # exact ends at k = 0 and k = n (the formula gives them up to rounding)
    lo = np.where(k == 0, 0.0, np.clip(mid - half, 0.0, 1.0))
    hi = np.where(k == n, 1.0, np.clip(mid + half, 0.0, 1.0))
    return lo, hi


def _names(names, what: str) -> list[str]:
    out = [str(s) for s in names]
    if not out:
        raise ModelError(f"a D-matrix needs at least one {what}")
    seen = set()
    for s in out:
        if s in seen:
            raise ModelError(f"duplicated {what} name {s!r}")
        seen.add(s)
    return out


def _prob_array(value, shape, what: str, faults, tests) -> np.ndarray:
    a = np.asarray(value, float)
    try:
        a = np.broadcast_to(a, shape).copy()
    except ValueError:
        raise ModelError(f"{what} has shape {np.shape(value)}; expected a scalar, ({shape[1]},) per "
                         f"test or {shape} per (fault, test)") from None
    bad = ~np.isfinite(a) | (a < 0) | (a > 1)
    if np.any(bad):
        i, j = map(int, np.argwhere(bad)[0])
        raise ModelError(f"{what}[{faults[i]!r}, {tests[j]!r}] = {a[i, j]} is not a probability in [0, 1]")
    return a


class DMatrix:
    """Binary diagnostic matrix with fault and test names, and optional test reliabilities.

    Parameters
    ----------
    faults : sequence of str
        Fault-state names, one per row (``n_f``); include the no-fault state (e.g. ``"F0"``,
        an all-zero row) if the diagnosis should be able to conclude "system OK".
    tests : sequence of str
        Test names, one per column (``n_t``).
    d : array_like, shape (n_f, n_t)
        Binary entries (bool, or numbers exactly 0 or 1); ``d[i, j] = 1`` when test ``j`` detects
        fault ``i``.
    pd : float or array_like, optional
        Detection probability ``Pd_ij = P(test j fails | fault i)`` used where ``d_ij = 1``: a scalar,
        one per test ``(n_t,)`` or one per entry ``(n_f, n_t)``. Default 1 (perfect tests).
    pf : float or array_like, optional
        False-alarm probability ``Pf_ij = P(test j fails | fault i)`` used where ``d_ij = 0``: a scalar,
        ``(n_t,)`` (the usual per-test Pf_j) or ``(n_f, n_t)``. Default 0.

    Attributes
    ----------
    faults, tests : list of str
    d : ndarray of bool, shape (n_f, n_t)
    pd, pf : ndarray of float, shape (n_f, n_t)
    pd_ci, pf_ci : ndarray, shape (n_f, n_t, 2) or None
        Wilson confidence intervals when learned by :meth:`from_outcomes`.
    runs : dict or None
        Number of Monte Carlo runs per class when learned by :meth:`from_outcomes`.

    Examples
    --------
    >>> dm = DMatrix(["F0", "F1", "F2", "F3"], ["t1", "t2"], [[0, 0], [1, 0], [1, 1], [1, 1]])
    >>> dm.ambiguity_groups()
    [('F2', 'F3')]
    >>> dm.is_isolable
    False
    >>> print(dm)
    D-matrix (4 faults x 2 tests)
    fault  t1  t2
    F0      0   0
    F1      1   0
    F2      1   1  <- ambiguity group 1
    F3      1   1  <- ambiguity group 1
    """

    def __init__(self, faults: Sequence[str], tests: Sequence[str], d, pd=None, pf=None):
        self.faults = _names(faults, "fault")
        self.tests = _names(tests, "test")
        nf, nt = len(self.faults), len(self.tests)
        raw = np.asarray(d)
        if raw.shape != (nf, nt):
            raise ModelError(f"D-matrix has shape {raw.shape}, but there are {nf} fault names and "
                             f"{nt} test names (expected ({nf}, {nt}))")
        if raw.dtype == bool:
            self.d = raw.copy()
        else:
            try:
                num = raw.astype(float)
            except (TypeError, ValueError):
                raise ModelError(f"D-matrix entries must be 0 or 1, got dtype {raw.dtype}") from None
            bad = ~((num == 0) | (num == 1))
            if np.any(bad):
                i, j = map(int, np.argwhere(bad)[0])
                raise ModelError(f"D-matrix entry ({self.faults[i]!r}, {self.tests[j]!r}) = "
                                 f"{raw[i, j].item()!r} is not binary (0 or 1); "
                                 "give detection probabilities as pd=")
            self.d = num == 1
        self.pd = _prob_array(1.0 if pd is None else pd, (nf, nt), "pd", self.faults, self.tests)
        self.pf = _prob_array(0.0 if pf is None else pf, (nf, nt), "pf", self.faults, self.tests)
        self.pd_ci = None
        self.pf_ci = None
        self.runs = None
        self.level = None

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_outcomes(cls, outcomes: Mapping[str, np.ndarray], tests: Sequence[str], *,
                      nominal: str | None = "F0", level: float = 0.5, pf_source: str = "nominal",
                      confidence: float = 0.95) -> DMatrix:
        """Learn a D-matrix and its Pd/Pf from Monte Carlo test outcomes.

        Parameters
        ----------
        outcomes : mapping str -> array_like of bool, shape (runs_i, n_t)
            For every fault class (the row name), the outcome of every test (column order
            ``tests``) in each simulated run: ``True`` when the test fired. The nominal class, if
            any, is included under the name ``nominal`` and becomes a row.
        tests : sequence of str
            Test names, ``n_t`` of them.
        nominal : str or None
            Name of the no-fault class in ``outcomes``; its runs give the per-test false-alarm
            probability ``Pf_j``. ``None`` when there is no nominal class (then ``pf_source`` must
            be ``"class"``).
        level : float
            Binary entry rule: ``d_ij = 1`` iff ``Pd_ij > level`` (strictly). The default 0.5 puts a
            test in the signature of a fault when it fires in most runs of that fault. The nominal
            row is all zero by definition of a false alarm, whatever its firing fraction.
        pf_source : {"nominal", "class"}
            ``"nominal"``: ``Pf_ij = Pf_j``, the firing fraction of test ``j`` in the nominal runs, for
            every fault (the paper's per-test ``P_ij`` pair). ``"class"``: ``Pf_ij`` is the firing
            fraction in the runs of class ``i`` itself (a fault that weakly excites a test it is
            not designed for keeps that information).
        confidence : float
            Level of the Wilson intervals ``pd_ci``, ``pf_ci``.

        Returns
        -------
        DMatrix
            With ``pd[i, j]`` = fraction of runs of class ``i`` in which test ``j`` fired (every
            entry), ``pf`` as chosen, ``pd_ci``/``pf_ci`` of shape (n_f, n_t, 2), ``runs`` and ``level``.

        Examples
        --------
        >>> import numpy as np
        >>> out = {"F0": np.zeros((100, 2), bool),
        ...        "F1": np.c_[np.arange(100) < 97, np.arange(100) < 3]}
        >>> dm = DMatrix.from_outcomes(out, ["t1", "t2"])
        >>> dm.d.astype(int).tolist(), float(dm.pd[1, 0]), dm.runs["F1"]
        ([[0, 0], [1, 0]], 0.97, 100)
        """
        if not 0.0 <= level < 1.0:
            raise DataError(f"level must lie in [0, 1), got {level}")
        if pf_source not in ("nominal", "class"):
            raise DataError(f"pf_source must be 'nominal' or 'class', got {pf_source!r}")
        tests = _names(tests, "test")
        if not isinstance(outcomes, Mapping) or not outcomes:
            raise DataError("outcomes must be a non-empty mapping fault name -> (runs, tests) array")
        if nominal is not None and nominal not in outcomes:
            raise DataError(f"nominal class {nominal!r} not in outcomes (classes: {list(outcomes)})")
        if nominal is None and pf_source == "nominal":
            raise DataError("pf_source='nominal' needs a nominal class; "
                            "pass nominal=... or pf_source='class'")
        faults = list(outcomes)
        nt = len(tests)
        k = np.zeros((len(faults), nt))
        n = np.zeros(len(faults))
        for i, name in enumerate(faults):
            o = np.asarray(outcomes[name])
            if o.ndim != 2 or o.shape[1] != nt:
                raise DataError(f"outcomes[{name!r}] has shape {o.shape}; "
                                f"expected (runs, {nt}) for tests {tests}")
            if o.shape[0] < 1:
                raise DataError(f"outcomes[{name!r}] has no runs")
            if o.dtype != bool:
                of = o.astype(float)
                if np.any(np.isnan(of)):
                    r, j = map(int, np.argwhere(np.isnan(of))[0])
                    raise DataError(f"outcomes[{name!r}] run {r}, test {tests[j]!r} is NaN")
                if np.any((of != 0) & (of != 1)):
                    r, j = map(int, np.argwhere((of != 0) & (of != 1))[0])
                    raise DataError(f"outcomes[{name!r}] run {r}, test {tests[j]!r} = {o[r, j]!r} is not "
                                    "a boolean outcome")
                o = of == 1
            k[i] = o.sum(axis=0)
            n[i] = o.shape[0]
        frac = k / n[:, None]
        d = frac > level
        if nominal is not None:
            d[faults.index(nominal)] = False
        lo, hi = wilson_interval(k, n[:, None], confidence)
        pd_ci = np.stack([lo, hi], axis=-1)
        if pf_source == "nominal":
            i0 = faults.index(nominal)
            pf = np.broadcast_to(frac[i0], frac.shape)
            pf_ci = np.broadcast_to(pd_ci[i0], pd_ci.shape).copy()
        else:
            pf = frac
            pf_ci = pd_ci.copy()
        dm = cls(faults, tests, d, pd=frac, pf=pf)
        dm.pd_ci, dm.pf_ci = pd_ci, pf_ci
        dm.runs = {f: int(m) for f, m in zip(faults, n)}
        dm.level = float(level)
        return dm

    # ------------------------------------------------------------------ queries
    @property
    def shape(self) -> tuple[int, int]:
        """``(n_f, n_t)``."""
        return self.d.shape

    @property
    def is_perfect(self) -> bool:
        """True when every used probability is 0 or 1 consistent with ``d`` (Pd = 1, Pf = 0)."""
        return bool(np.all(np.where(self.d, self.pd, 1.0 - self.pf) == 1.0))

    def fail_probability(self) -> np.ndarray:
        """Probability that each test fails under each fault, shape (n_f, n_t): ``Pd`` where ``d = 1``,
        ``Pf`` where ``d = 0``.

        Examples
        --------
        >>> DMatrix(["a", "b"], ["t"], [[1], [0]], pd=0.9, pf=0.05).fail_probability().tolist()
        [[0.9], [0.05]]
        """
        return np.where(self.d, self.pd, self.pf)

    def row(self, fault: str) -> np.ndarray:
        """Binary signature (n_t,) of one fault."""
        return self.d[self.index(fault)].copy()

    def index(self, fault: str) -> int:
        """Row index of a fault name (clear error on an unknown name)."""
        try:
            return self.faults.index(str(fault))
        except ValueError:
            raise ModelError(f"unknown fault {fault!r}; faults are {self.faults}") from None

    def classes(self) -> list[tuple[str, ...]]:
        """Partition of the faults into classes of identical binary rows (singletons included),
        in order of first appearance."""
        groups: dict[bytes, list[str]] = {}
        for name, r in zip(self.faults, self.d):
            groups.setdefault(r.tobytes(), []).append(name)
        return [tuple(g) for g in groups.values()]

    def ambiguity_groups(self) -> list[tuple[str, ...]]:
        """Groups of two or more faults with identical rows: no test set can tell them apart.

        Examples
        --------
        >>> DMatrix(["a", "b", "c"], ["t"], [[1], [0], [1]]).ambiguity_groups()
        [('a', 'c')]
        """
        return [g for g in self.classes() if len(g) > 1]

    @property
    def is_isolable(self) -> bool:
        """True when all rows are distinct (every fault can be uniquely isolated, single-fault case)."""
        return not self.ambiguity_groups()

    def diagnose(self, outcomes, *, prior=None, tol: float = 1e-9, floor: float = 1e-6):
        """Maximum-likelihood diagnosis from test outcomes, every row (the nominal one included) a candidate.

        Each test fires under fault ``i`` with probability ``Pd_ij`` where ``d_ij = 1`` and ``Pf_ij``
        where ``d_ij = 0`` (:meth:`fail_probability`); tests are conditionally independent given the
        fault. The diagnosis maximises the likelihood (or the posterior with ``prior``), and returns for
        every outcome vector its ambiguity set: all rows whose score ties the best (identical rows always
        tie).

        Parameters
        ----------
        outcomes : array_like of bool (runs, n_t) or (n_t,), or mapping test -> bool / (runs,)
            True = the test fired (NG). A mapping must give every test.
        prior : array_like (n_f,) or mapping fault -> probability, optional
            Prior probabilities of the rows (default uniform: maximum likelihood).
        tol : float
            Score tolerance of the ambiguity sets (natural-log units).
        floor : float
            Probabilities are clipped to ``[floor, 1 - floor]`` (a perfect D-matrix then counts each
            contradicted test as a factor ``floor``: the nearest signature wins).

        Returns
        -------
        Diagnosis
            ``best`` (names), ``index``, ``loglik`` and ``posterior`` (runs, n_f), ``ambiguity``.

        Examples
        --------
        >>> dm = DMatrix(["F0", "F1", "F2", "F3"], ["t1", "t2"], [[0, 0], [1, 0], [1, 1], [1, 1]],
        ...              pd=0.95, pf=0.02)
        >>> d = dm.diagnose([[0, 0], [1, 0], [1, 1]])
        >>> d.best, d.ambiguity
        (['F0', 'F1', 'F2'], [('F0',), ('F1',), ('F2', 'F3')])
        """
        from .decide import diagnose_likelihood

        if isinstance(outcomes, Mapping):
            unknown = [k for k in outcomes if k not in self.tests]
            missing = [t for t in self.tests if t not in outcomes]
            if unknown or missing:
                raise DataError(f"outcomes name unknown tests {unknown} / miss tests {missing}; tests are "
                                f"{self.tests}")
            o = np.column_stack([np.atleast_1d(np.asarray(outcomes[t])) for t in self.tests])
        else:
            o = np.asarray(outcomes)
            if o.ndim == 1:
                o = o[None]
            if o.ndim != 2 or o.shape[1] != len(self.tests):
                raise DataError(f"outcomes have shape {np.shape(outcomes)}; expected "
                                f"(runs, {len(self.tests)}) for tests {self.tests}")
        pr = None
        if prior is not None:
            if isinstance(prior, Mapping):
                bad = [k for k in prior if k not in self.faults]
                if bad:
                    raise DataError(f"prior names unknown faults {bad}; faults are {self.faults}")
                pr = np.array([float(prior.get(f, 0.0)) for f in self.faults])
            else:
                pr = prior
        return diagnose_likelihood(o, self.fail_probability(), self.faults, prior=pr, tol=tol, floor=floor)

    def undetectable(self, nominal: str | None = None) -> list[str]:
        """Faults (other than ``nominal``) whose row is all zero: no test detects them."""
        return [f for f, r in zip(self.faults, self.d) if not r.any() and f != nominal]

    # ------------------------------------------------------------------ display
    def to_text(self, probabilities: bool = False) -> str:
        """Readable table: one line per fault; ambiguity groups are marked.

        With ``probabilities=True`` each entry shows ``d (P(fail))`` to three decimals.
        """
        groups = {f: k + 1 for k, g in enumerate(self.ambiguity_groups()) for f in g}
        q = self.fail_probability()
        cells = [[(f"{int(v)} ({q[i, j]:.3f})" if probabilities else str(int(v)))
                  for j, v in enumerate(r)] for i, r in enumerate(self.d)]
        w0 = max(5, *(len(f) for f in self.faults))
        widths = [max(len(t), *(len(c[j]) for c in cells)) for j, t in enumerate(self.tests)]
        lines = [f"D-matrix ({len(self.faults)} faults x {len(self.tests)} tests)",
                 "fault".ljust(w0) + "".join("  " + t.rjust(w) for t, w in zip(self.tests, widths))]
        for f, c in zip(self.faults, cells):
            s = f.ljust(w0) + "".join("  " + x.rjust(w) for x, w in zip(c, widths))
            if f in groups:
                s += f"  <- ambiguity group {groups[f]}"
            lines.append(s)
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.to_text()

    def __repr__(self) -> str:
        return f"DMatrix(faults={self.faults}, tests={self.tests}, perfect={self.is_perfect})"

    def to_dict(self) -> dict:
        """JSON-ready dictionary (names, binary matrix, Pd, Pf)."""
        return {"faults": list(self.faults), "tests": list(self.tests),
                "d": self.d.astype(int).tolist(), "pd": self.pd.tolist(), "pf": self.pf.tolist()}

    @classmethod
    def from_dict(cls, data: Mapping) -> DMatrix:
        """Inverse of :meth:`to_dict`."""
        return cls(data["faults"], data["tests"], data["d"], pd=data.get("pd"), pf=data.get("pf"))
