"""The multiple-hypothesis Shiryayev sequential probability test itself (:class:`MHSSPT`): its
parameters, the choice of exact, linear-table or cubic-table densities, serial or parallel
kernels, checked inputs, batch and streaming.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
from numba import njit, prange

from ...base.stage import ResidualProcessor
from ...errors import DataError
from ...signals import Signals
from .densities import UniformMeanGaussian
from .kernels import _loglik_umg_shared, _loglik_umg_shared_parallel, _shared_components
from .recursion import _mhsspt_recursion, _mhsspt_recursion_parallel, _probabilities, _probabilities_parallel
from .tables import (
    _loglik_table,
    _mhsspt_cubic_run,
    _mhsspt_cubic_run_parallel,
    _mhsspt_table_run,
    _mhsspt_table_run_parallel,
    tabulate_umg,
    tabulate_umg_cubic,
)

__all__ = ["MHSSPT", "table_direct"]


@njit(cache=True)
def _first_nonfinite_run(x, r):  # pragma: no cover - compiled
    """The first (sample, channel) of run r of x (R, T, C) that is not finite, as k * C + c; -1 if none."""
    T, C = x.shape[1], x.shape[2]
    for k in range(T):
        for c in range(C):
            if not np.isfinite(x[r, k, c]):
                return k * C + c
    return -1


@njit(cache=True, parallel=True)
def _first_nonfinite(x):  # pragma: no cover - compiled
    """Per run, :func:`_first_nonfinite_run`: one parallel pass without temporaries (a bulk call
    checks ~1e7 values)."""
    first = np.full(x.shape[0], -1, np.int64)
    for r in prange(x.shape[0]):
        first[r] = _first_nonfinite_run(x, r)
    return first


@njit(cache=True)
def _first_nonfinite_serial(x):  # pragma: no cover - compiled
    """As :func:`_first_nonfinite`, without the thread launch (one run: nothing to share)."""
    first = np.full(x.shape[0], -1, np.int64)
    for r in range(x.shape[0]):
        first[r] = _first_nonfinite_run(x, r)
    return first


def table_direct(advance):
    """Mark an :class:`MHSSPT` subclass's ``_advance`` as the base recursion on the features of
    ``_prepare``, so that a tabulated test may compute its outputs in one fused call
    (``MHSSPT._direct``) instead."""
    advance.table_direct = True
    return advance


#: Work (samples x components) above which a call shares the streams among threads; below it the
#: thread start-up costs more than it saves (a streaming step).
PARALLEL_MIN_WORK = 4096


#: Log posteriors above which :meth:`MHSSPT._outputs` shares its rows among threads: one exp per
#: value is ~10 ns, so below this (a one-run minute of 3000 samples is 3.3e4) waking the threads
#: costs more than the whole serial pass.
PARALLEL_MIN_OUTPUTS = 1 << 18


class MHSSPT(ResidualProcessor):
    """Multiple-hypothesis Shiryayev test over a vector of residual features.

    Parameters
    ----------
    inputs : sequence of str
        Feature channels (e.g. the norm of each filter's residual), C of them.
    densities : mapping hypothesis name -> density
        Ordered; the FIRST entry is the no-fault hypothesis H0. A density has ``logpdf(x)``
        for ``x`` (..., C) -> (...) (e.g. :class:`UniformMeanGaussian`).
    p : float
        Probability of a change from H0 at each sample (0 < p < 1).
    pi : sequence of float, optional
        Probability of each fault hypothesis given a change (default uniform).
    q : float
        Return probability from a fault hypothesis to H0 (0 = the exact MHSSPT).
    groups : mapping name -> list of hypothesis names, optional
        Extra outputs summing hypotheses, e.g. ``{"brake": ["brake_small", "brake_large"]}``.
    tabulate : float, optional
        With :class:`UniformMeanGaussian` densities: evaluate them by linear interpolation in
        tables of spacing ``tabulate`` times each feature's smallest std (:func:`tabulate_umg`;
        error <= tabulate^2 / 8 nats per component, measured as ``table_error``) instead of the
        exact formula -- more than ten times faster (benchmarks/bench_car_monitor.py); the table and
        the recursion then run in one compiled call. ``None`` (default): exact.
    interpolation : {"linear", "cubic"}
        With ``tabulate``: ``"linear"`` (default) as above, or ``"cubic"``: Hermite cubics that
        match the exact log density and its slope at every grid point, on the distinct components
        of each channel (:func:`tabulate_umg_cubic`; error about ``tabulate^4 / 200`` nats, a few
        1e-8 at 1/16, measured as ``table_error``), for a test that must agree with the exact
        one; about eight times faster than the exact formula on the RAV4 monitor.

    Notes
    -----
    Outputs ``"P:<hypothesis>"`` for every hypothesis, then ``"P:<group>"`` for every group.

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit import Signals
    >>> test = MHSSPT(["r"], {"none": UniformMeanGaussian([0], [0], [1]),
    ...                       "bias": UniformMeanGaussian([2], [4], [1])}, p=1e-3)
    >>> x = np.r_[np.zeros(20), np.full(10, 3.0)]
    >>> P = test.run(Signals(np.arange(30.0), x, ["r"]))["P:bias"][0]
    >>> bool(P[19] < 0.01), bool(P[-1] > 0.99)
    (True, True)
    """

    def __init__(
        self,
        inputs: Sequence[str],
        densities: Mapping[str, object],
        p: float,
        pi: Sequence[float] | None = None,
        q: float = 0.0,
        groups: Mapping[str, Sequence[str]] | None = None,
        tabulate: float | None = None,
        interpolation: str = "linear",
    ):
        self.input_names = [str(s) for s in inputs]
        self.hypotheses = [str(h) for h in densities]
        self.densities = list(densities.values())
        H = len(self.hypotheses)
        if H < 2:
            raise DataError("MHSSPT needs H0 and at least one fault hypothesis")
        for h, d in zip(self.hypotheses, self.densities):
            size = getattr(d, "size", len(self.input_names))
            if size != len(self.input_names):
                raise DataError(f"density of hypothesis {h!r} has {size} components for "
                                f"{len(self.input_names)} inputs {self.input_names}")
        if not 0 < p < 1:
            raise DataError(f"change probability p must be in (0, 1), got {p}")
        if not 0 <= q < 1:
            raise DataError(f"return probability q must be in [0, 1), got {q}")
        pi = np.full(H - 1, 1.0 / (H - 1)) if pi is None else np.asarray(pi, float)
        if pi.shape != (H - 1,) or np.any(pi < 0) or abs(pi.sum() - 1) > 1e-9:
            raise DataError(f"pi must be {H - 1} non-negative probabilities summing to 1, got {pi}")
        self.p, self.q, self.pi = float(p), float(q), pi
        self.groups = {str(g): list(m) for g, m in (groups or {}).items()}
        for g, members in self.groups.items():
            for h in members:
                if h not in self.hypotheses:
                    raise DataError(f"group {g!r} names unknown hypothesis {h!r}; "
                                    f"hypotheses: {self.hypotheses}")
        self._gidx = [[self.hypotheses.index(h) for h in m] for m in self.groups.values()]
        width = max([len(g) for g in self._gidx], default=1)
        self._gmat = np.full((len(self._gidx), width), -1, np.int64)
        for i, g in enumerate(self._gidx):
            self._gmat[i, :len(g)] = g
        self.output_names = [f"P:{h}" for h in self.hypotheses] + [f"P:{g}" for g in self.groups]
        with np.errstate(divide="ignore"):
            self._logp_pi = np.r_[-np.inf, np.log(self.p) + np.log(pi)]
            self._logq = np.log(self.q) if self.q > 0 else -np.inf
        self._log1mp, self._log1mq = np.log1p(-self.p), np.log1p(-self.q)
        if all(isinstance(d, UniformMeanGaussian) for d in self.densities):
            st = [np.stack([getattr(d, a) for d in self.densities]) for a in ("low", "high", "std")]
            point = np.stack([d._point for d in self.densities])
            logw = np.log(np.where(point, 1.0, st[1] - st[0]))
            self._umg = (*st, point, logw)
            self._umg_shared = (self._umg, _shared_components(*self._umg))
        else:
            self._umg = None
            self._umg_shared = None
        self.tabulate = None if tabulate is None else float(tabulate)
        if interpolation not in ("linear", "cubic"):
            raise DataError(f"interpolation must be 'linear' or 'cubic', got {interpolation!r}")
        self.interpolation = str(interpolation)
        self._table = None
        self._cubic = None
        self.table_error = 0.0
        if self.tabulate is not None:
            if self._umg is None:
                raise DataError("tabulated densities need UniformMeanGaussian densities")
            if self.interpolation == "cubic":
                shared = self._umg_shared[1]  # (ulow, uhigh, ustd, upoint, ulogw, uoff, jmap)
                tb = tabulate_umg_cubic(*shared[:6], self.tabulate)
                self._cubic = (tb["coef"].ravel(), tb["g0"], tb["inv_h"], tb["nG"], tb["coff"], *shared)
                self._table = self._cubic
            else:
                tb = tabulate_umg(self._umg[0], self._umg[1], self._umg[2], self._umg[3], self.tabulate)
                self._table = (tb["tab"], tb["g0"], tb["inv_h"], tb["nG"], tb["toff"])
                self._dens = np.ascontiguousarray(np.stack([self._umg[i] for i in (0, 1, 2, 4)]))
            self.table_error = tb["error"]
        self.reset(1)

    def loglik(self, x: np.ndarray) -> np.ndarray:
        """Log densities of every hypothesis: x (..., C) -> (..., H).

        When every density is a :class:`UniformMeanGaussian` this runs a compiled kernel;
        other density objects are evaluated through their ``logpdf``.
        """
        x = np.asarray(x, float)
        if self._umg is None:
            return np.stack([d.logpdf(x) for d in self.densities], axis=-1)
        x3 = np.ascontiguousarray(x.reshape(-1, 1, x.shape[-1]) if x.ndim != 3 else x)
        out = np.empty((*x3.shape[:2], len(self.hypotheses)))
        if self._cubic is not None:  # the log likelihoods alone (mode 0: no recursion, logF untouched)
            _mhsspt_cubic_run(x3, *self._cubic, np.zeros((x3.shape[0], out.shape[2])), self._log1mp,
                              self._logp_pi, self._logq, self._log1mq, self._gmat, 0, out)
        elif self._table is not None:
            _loglik_table(x3, *self._table, *self._umg, out)
        else:
            par = x3.shape[0] > 1 and x3.size > PARALLEL_MIN_WORK
            src, shared = getattr(self, "_umg_shared", None) or (None, None)
            if src is not self._umg:  # restored without __init__, or densities replaced
                shared = _shared_components(*self._umg)
                self._umg_shared = (self._umg, shared)
            # the components shared between hypotheses once (bitwise _loglik_umg)
            (_loglik_umg_shared_parallel if par else _loglik_umg_shared)(x3, *shared, out)
        return out.reshape((*x.shape[:-1], len(self.hypotheses)))

    _state_attrs = ("_logF", "_k")

    def to_dict(self) -> dict:
        """Configuration as plain data; densities must be :class:`UniformMeanGaussian`."""
        if self._umg is None:
            raise DataError("only MHSSPTs with UniformMeanGaussian densities can be exported")
        return {"inputs": list(self.input_names),
                "densities": {h: d.to_dict() for h, d in zip(self.hypotheses, self.densities)},
                "p": self.p, "pi": self.pi.tolist(), "q": self.q, "groups": self.groups,
                "tabulate": self.tabulate, "interpolation": self.interpolation}

    @classmethod
    def from_dict(cls, d: dict) -> MHSSPT:
        dens = {h: UniformMeanGaussian(v["low"], v["high"], v["std"]) for h, v in d["densities"].items()}
        return cls(d["inputs"], dens, d["p"], d["pi"], d["q"], d["groups"], tabulate=d.get("tabulate"),
                   interpolation=d.get("interpolation", "linear"))

    def reset(self, runs: int = 1) -> None:
        self._logF = np.full((runs, len(self.hypotheses)), -np.inf)
        self._logF[:, 0] = 0.0
        self._k = 0

    def _outputs(self, logF: np.ndarray) -> np.ndarray:
        """Probabilities of the hypotheses, then the group sums: logF (..., H) -> (..., H + G)."""
        H = logF.shape[-1]
        L = np.ascontiguousarray(logF.reshape(-1, H))
        out = np.empty((L.shape[0], H + len(self._gidx)))
        kern = _probabilities_parallel if L.size > PARALLEL_MIN_OUTPUTS else _probabilities
        kern(L, self._gmat, out)
        return out.reshape((*logF.shape[:-1], out.shape[1]))

    def _check_finite(self, x: np.ndarray) -> None:
        """Refuse a non-finite input, naming the first one (run, then sample, then channel)."""
        if x.size <= PARALLEL_MIN_WORK:
            first = None
        else:
            first = (_first_nonfinite if x.shape[0] > 1 else _first_nonfinite_serial)(x)
        if first is not None and (first < 0).all():
            return
        bad = ~np.isfinite(x)
        if bad.any():
            run, k, c = np.argwhere(bad)[0]
            raise DataError(f"MHSSPT input {self.input_names[c]!r} is not finite at sample "
                            f"{self._k + k} (run {run})")

    def _prepare(self, x: np.ndarray) -> np.ndarray:
        """The features the densities see (a subclass may replace some, e.g. a warm-up)."""
        return x

    @table_direct
    def _advance(self, x: np.ndarray) -> np.ndarray:
        self._check_finite(x)
        if x.shape[0] != self._logF.shape[0]:
            raise DataError(f"sample has {x.shape[0]} runs; the test was reset for {self._logF.shape[0]}")
        if self._table is not None:  # one compiled call: table look-up and recursion, streams in parallel
            out = np.empty((*x.shape[:2], len(self.hypotheses)))
            self._table_call(x, False, out)
        else:
            ll = np.ascontiguousarray(self.loglik(x))
            out = np.empty_like(ll)
            rec = _mhsspt_recursion_parallel if x.shape[0] > 1 and x.size > PARALLEL_MIN_WORK else \
                _mhsspt_recursion
            rec(ll, self._logF, self._log1mp, self._logp_pi, self._logq, self._log1mq, out)
        self._k += x.shape[1]
        return out

    def _table_call(self, x: np.ndarray, probs: bool, out: np.ndarray) -> None:
        par = x.shape[0] > 1 and x.size > PARALLEL_MIN_WORK
        if self._cubic is not None:
            kern = _mhsspt_cubic_run_parallel if par else _mhsspt_cubic_run
            kern(np.ascontiguousarray(x, dtype=float), *self._cubic, self._logF, self._log1mp, self._logp_pi,
                 self._logq, self._log1mq, self._gmat, 2 if probs else 1, out)
            return
        kern = _mhsspt_table_run_parallel if par else _mhsspt_table_run
        kern(np.ascontiguousarray(x, dtype=float), *self._table, self._dens, self._umg[3], self._logF,
             self._log1mp, self._logp_pi, self._logq, self._log1mq, self._gmat, probs, out)

    def _direct(self, x: np.ndarray) -> np.ndarray | None:
        """Outputs straight from the tabulated kernel: the normalised posteriors the recursion
        forms (no log-posterior intermediate and no second exp), equal to
        ``_outputs(_advance(x))`` to rounding (probabilities below 4.3e-18 are 0 here); None where
        that path is needed (exact densities, or a subclass whose ``_advance`` is not marked
        :func:`table_direct`: it does more than ``_prepare`` and the tabulated recursion)."""
        if self._table is None or not getattr(type(self)._advance, "table_direct", False):
            return None
        x = self._prepare(x)
        self._check_finite(x)
        if x.shape[0] != self._logF.shape[0]:
            raise DataError(f"sample has {x.shape[0]} runs; the test was reset for {self._logF.shape[0]}")
        out = np.empty((*x.shape[:2], len(self.output_names)))
        self._table_call(x, True, out)
        self._k += x.shape[1]
        return out

    def _step(self, r: np.ndarray) -> np.ndarray:
        x = r[:, None, :]
        out = self._direct(x)
        return (self._outputs(self._advance(x)) if out is None else out)[:, 0]

    def run(self, signals: Signals) -> Signals:
        idx = signals.index(self.input_names)
        # the channels as they are (a view) when they are all of them in order: no 30 MB copy
        x = signals.values if list(idx) == list(range(signals.n_channels)) else signals.values[:, :, idx]
        self.reset(signals.runs)
        out = self._direct(x)
        return Signals(signals.t, self._outputs(self._advance(x)) if out is None else out, self.output_names,
                       check=False)

    def log_posterior(self) -> np.ndarray:
        """Current log posterior of every hypothesis, (runs, H)."""
        return self._logF.copy()
