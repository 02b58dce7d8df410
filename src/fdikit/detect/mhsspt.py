"""Multiple-hypothesis Shiryayev sequential probability test (MHSSPT), in the log domain.

Paper ng-chen-speyer, Section IV-E, after Malladi & Speyer (IEEE TAC 44(8), 1999); the recursion
and densities are written out in shared/notes/residual-processing.md. Hypothesis 0 is "no
fault"; hypotheses 1..M are faults. At every sample a change from H0 occurs with probability
``p``, to H_j with probability ``pi_j``; an optional return probability ``q`` lets a fault
hypothesis fall back to H0 (intermittent faults). With the posterior ``F`` of the previous
sample::

    phi_0 = F_0 (1 - p) + q sum_{j>=1} F_j
    phi_j = F_j (1 - q) + F_0 p pi_j
    F_j  <- phi_j f_j(x_k) / sum_i phi_i f_i(x_k)

computed with log-sum-exp so that likelihoods of 1e-300 neither underflow nor give 0/0.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy.special import log_ndtr

from ..errors import DataError
from ..monitor.core import ResidualProcessor
from ..signals import Signals

__all__ = ["MHSSPT", "MHSSPTCalibration", "UniformMeanGaussian", "calibrate_densities",
           "umg_component_logpdf"]

_LOG_SQRT_2PI = 0.5 * np.log(2 * np.pi)


def _log_diff_ndtr(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """log(Phi(u) - Phi(v)) for u > v, accurate in both tails."""
    # upper tail (v > 0): Phi(u) - Phi(v) = Phi(-v) - Phi(-u)
    upper = v > 0
    hi = np.where(upper, -v, u)
    lo = np.where(upper, -u, v)
    lhi, llo = log_ndtr(hi), log_ndtr(lo)
    return lhi + np.log1p(-np.exp(np.minimum(llo - lhi, 0.0)))


@njit(cache=True)
def _log_ndtr_nb(x):  # pragma: no cover - compiled
    """log Phi(x): erfc down to x = -37 (Phi ~ 1e-300), the asymptotic series below."""
    if x > 0.0:
        return math.log1p(-0.5 * math.erfc(x / math.sqrt(2.0)))
    if x > -37.0:
        return math.log(0.5 * math.erfc(-x / math.sqrt(2.0)))
    z = 1.0 / (x * x)
    # Phi(x) = phi(x)/|x| (1 - 1/x^2 + 3/x^4 - 15/x^6 + ...): error < 11! ! / 37^14 ~ 1e-18 here
    s = 1.0 + z * (-1.0 + z * (3.0 + z * (-15.0 + z * (105.0 + z * (-945.0 + z * 10395.0)))))
    return -0.5 * x * x - math.log(-x) - 0.5 * math.log(2.0 * math.pi) + math.log(s)


@njit(cache=True)
def umg_component_logpdf(x, low, high, std, point, logw):  # pragma: no cover - compiled
    """Log density of one uniform-mean Gaussian component at a scalar ``x`` (compiled).

    ``point``: the mean range is a point (plain Gaussian); ``logw = log(high - low)``.
    """
    if point:
        z = (x - low) / std
        return -0.5 * z * z - math.log(std) - 0.5 * math.log(2.0 * math.pi)
    u = (x - low) / std
    v = (x - high) / std
    if v > 0.0:  # upper tail: Phi(u) - Phi(v) = Phi(-v) - Phi(-u)
        hi, lo = -v, -u
    else:
        hi, lo = u, v
    lhi = _log_ndtr_nb(hi)
    d = _log_ndtr_nb(lo) - lhi
    if d > 0.0:
        d = 0.0
    return lhi + math.log1p(-math.exp(d)) - logw


@njit(cache=True)
def _loglik_umg(x, low, high, std, point, logw, out):  # pragma: no cover - compiled
    """Log densities of uniform-mean Gaussians: x (R, T, C) -> out (R, T, H)."""
    R, T, C = x.shape
    H = low.shape[0]
    for r in range(R):
        for k in range(T):
            for j in range(H):
                acc = 0.0
                for c in range(C):
                    acc += umg_component_logpdf(x[r, k, c], low[j, c], high[j, c], std[j, c],
                                                point[j, c], logw[j, c])
                out[r, k, j] = acc


class UniformMeanGaussian:
    """Density of a residual vector whose components are Gaussian with an unknown mean that is
    uniformly distributed on ``[low_c, high_c]`` (paper ng-chen-speyer, Section IV-E)::

        f(x) = prod_c [Phi((x_c - a_c)/s_c) - Phi((x_c - b_c)/s_c)] / (b_c - a_c)

    ``a_c == b_c`` falls back to the Gaussian density with mean ``a_c``.

    Parameters
    ----------
    low, high, std : array_like (C,)
        Mean range and standard deviation of each component (std > 0, high >= low).

    Examples
    --------
    >>> d = UniformMeanGaussian([0.0], [0.0], [1.0])
    >>> round(float(d.logpdf([0.0])), 6)      # log of the standard normal density at 0
    -0.918939
    """

    def __init__(self, low, high, std):
        self.low = np.atleast_1d(np.asarray(low, float))
        self.high = np.atleast_1d(np.asarray(high, float))
        self.std = np.atleast_1d(np.asarray(std, float))
        if not (self.low.shape == self.high.shape == self.std.shape) or self.low.ndim != 1:
            raise DataError(f"low, high and std must be 1-D of equal length, got shapes "
                            f"{self.low.shape}, {self.high.shape}, {self.std.shape}")
        if not (np.all(np.isfinite(self.low)) and np.all(np.isfinite(self.high))
                and np.all(np.isfinite(self.std))):
            raise DataError("density parameters must be finite")
        if np.any(self.std <= 0):
            raise DataError(f"std must be positive, got {self.std.tolist()}")
        if np.any(self.high < self.low):
            c = int(np.argmax(self.high < self.low))
            raise DataError(f"component {c}: high {self.high[c]} < low {self.low[c]}")
        self._point = (self.high - self.low) <= 1e-12 * np.maximum(1.0, np.abs(self.high))

    @property
    def size(self) -> int:
        return self.low.size

    def logpdf(self, x) -> np.ndarray:
        """Log density of ``x`` shaped (..., C), summed over the components -> (...)."""
        x = np.asarray(x, float)
        if x.shape[-1] != self.size:
            raise DataError(f"density has {self.size} components, sample has {x.shape[-1]}")
        s = self.std
        gauss = -0.5 * ((x - self.low) / s) ** 2 - np.log(s) - _LOG_SQRT_2PI
        width = np.where(self._point, 1.0, self.high - self.low)
        with np.errstate(divide="ignore", invalid="ignore"):  # point components are not used
            unif = _log_diff_ndtr((x - self.low) / s, (x - self.high) / s) - np.log(width)
        return np.where(self._point, gauss, unif).sum(axis=-1)

    def to_dict(self) -> dict:
        return {"low": self.low.tolist(), "high": self.high.tolist(), "std": self.std.tolist()}


@njit(cache=True)
def _mhsspt_recursion(loglik, logF, log1mp, logp_pi, logq, log1mq, out):  # pragma: no cover
    """loglik (R, T, H) -> out (R, T, H) log posteriors; logF (R, H) is updated in place."""
    R, T, H = loglik.shape
    phi = np.empty(H)
    for r in range(R):
        for k in range(T):
            # log-sum-exp of the fault hypotheses (for the return probability)
            m = -np.inf
            for j in range(1, H):
                if logF[r, j] > m:
                    m = logF[r, j]
            sf = 0.0
            if m > -np.inf:
                for j in range(1, H):
                    sf += np.exp(logF[r, j] - m)
                lse_f = m + np.log(sf)
            else:
                lse_f = -np.inf
            a = logF[r, 0] + log1mp
            b = logq + lse_f
            mx = max(a, b)
            phi[0] = mx + np.log(np.exp(a - mx) + np.exp(b - mx)) if mx > -np.inf else -np.inf
            for j in range(1, H):
                a = logF[r, j] + log1mq
                b = logF[r, 0] + logp_pi[j]
                mx = max(a, b)
                phi[j] = mx + np.log(np.exp(a - mx) + np.exp(b - mx)) if mx > -np.inf else -np.inf
            # Bayes update
            m = -np.inf
            for j in range(H):
                phi[j] += loglik[r, k, j]
                if phi[j] > m:
                    m = phi[j]
            s = 0.0
            for j in range(H):
                s += np.exp(phi[j] - m)
            lz = m + np.log(s)
            for j in range(H):
                logF[r, j] = phi[j] - lz
                out[r, k, j] = logF[r, j]


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
        else:
            self._umg = None
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
        _loglik_umg(x3, *self._umg, out)
        return out.reshape((*x.shape[:-1], len(self.hypotheses)))

    _state_attrs = ("_logF", "_k")

    def to_dict(self) -> dict:
        """Configuration as plain data; densities must be :class:`UniformMeanGaussian`."""
        if self._umg is None:
            raise DataError("only MHSSPTs with UniformMeanGaussian densities can be exported")
        return {"inputs": list(self.input_names),
                "densities": {h: d.to_dict() for h, d in zip(self.hypotheses, self.densities)},
                "p": self.p, "pi": self.pi.tolist(), "q": self.q, "groups": self.groups}

    @classmethod
    def from_dict(cls, d: dict) -> MHSSPT:
        dens = {h: UniformMeanGaussian(v["low"], v["high"], v["std"]) for h, v in d["densities"].items()}
        return cls(d["inputs"], dens, d["p"], d["pi"], d["q"], d["groups"])

    def reset(self, runs: int = 1) -> None:
        self._logF = np.full((runs, len(self.hypotheses)), -np.inf)
        self._logF[:, 0] = 0.0
        self._k = 0

    def _outputs(self, logF: np.ndarray) -> np.ndarray:
        P = np.exp(logF)
        if not self._gidx:
            return P
        return np.concatenate([P] + [P[..., i].sum(axis=-1, keepdims=True) for i in self._gidx], axis=-1)

    def _advance(self, x: np.ndarray) -> np.ndarray:
        bad = ~np.isfinite(x)
        if bad.any():
            run, k, c = np.argwhere(bad)[0]
            raise DataError(f"MHSSPT input {self.input_names[c]!r} is not finite at sample "
                            f"{self._k + k} (run {run})")
        if x.shape[0] != self._logF.shape[0]:
            raise DataError(f"sample has {x.shape[0]} runs; the test was reset for {self._logF.shape[0]}")
        ll = np.ascontiguousarray(self.loglik(x))
        out = np.empty_like(ll)
        _mhsspt_recursion(ll, self._logF, self._log1mp, self._logp_pi, self._logq, self._log1mq, out)
        self._k += x.shape[1]
        return out

    def _step(self, r: np.ndarray) -> np.ndarray:
        return self._outputs(self._advance(r[:, None, :])[:, 0])

    def run(self, signals: Signals) -> Signals:
        x = signals.values[:, :, signals.index(self.input_names)]
        self.reset(signals.runs)
        return Signals(signals.t, self._outputs(self._advance(x)), self.output_names, check=False)

    def log_posterior(self) -> np.ndarray:
        """Current log posterior of every hypothesis, (runs, H)."""
        return self._logF.copy()


@dataclass
class MHSSPTCalibration:
    """Densities and hypothesis groups calibrated by :func:`calibrate_densities`.

    ``densities`` is ordered: the no-fault hypothesis first, then ``<fault>:small`` and
    ``<fault>:large`` for every fault; ``groups`` maps each fault to its pair, so that
    ``MHSSPT(inputs, cal.densities, p, groups=cal.groups)`` reports ``P:<fault>`` as the sum.
    ``ranges`` records, per hypothesis, the magnitudes it covers.
    """

    densities: dict[str, UniformMeanGaussian]
    groups: dict[str, list[str]]
    ranges: dict[str, tuple[float, float]]


def calibrate_densities(
    nominal: np.ndarray,
    faults: Mapping[str, Mapping[float, np.ndarray]],
    *,
    no_fault: str = "none",
    split: Mapping[str, float] | None = None,
    inflate: float = 1.0,
) -> MHSSPTCalibration:
    """Calibrate uniform-mean Gaussian densities from simulated residual features.

    Paper ng-chen-speyer, Section IV-E: every fault is simulated over a range of magnitudes;
    two hypotheses per fault (small and large magnitudes) get, per feature component, the range
    ``[a, b]`` spanned by the feature means at those magnitudes and the standard deviation of
    the features about their means (pooled over the magnitudes).

    Parameters
    ----------
    nominal : array (N, C)
        Feature samples without a fault (after transients): H0 gets their mean as a point
        mean and their standard deviation.
    faults : mapping fault -> mapping magnitude -> array (N_m, C)
        Feature samples of each fault at each simulated magnitude (after the fault has
        settled). At least two magnitudes per fault.
    no_fault : str
        Name of the no-fault hypothesis.
    split : mapping fault -> magnitude, optional
        Magnitudes ``<= split`` (in absolute value) form the small hypothesis, the others the
        large one (default: the median magnitude; a magnitude at the split is in both).
    inflate : float
        Factor (>= 1) applied to every standard deviation (a robustness margin for model error).

    Returns
    -------
    MHSSPTCalibration

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> nominal = rng.normal(0, 0.1, (500, 1))
    >>> feats = {m: rng.normal(m, 0.1, (200, 1)) for m in (1.0, 2.0, 3.0, 4.0)}
    >>> cal = calibrate_densities(nominal, {"bias": feats})
    >>> list(cal.densities), cal.groups
    (['none', 'bias:small', 'bias:large'], {'bias': ['bias:small', 'bias:large']})
    >>> np.round(cal.densities["bias:large"].low, 1).tolist()
    [3.0]
    """
    nominal = np.asarray(nominal, float)
    if nominal.ndim != 2 or nominal.shape[0] < 2:
        raise DataError(f"nominal features must be (N >= 2, C), got shape {nominal.shape}")
    C = nominal.shape[1]
    if not np.all(np.isfinite(nominal)):
        raise DataError("nominal features contain NaN or inf")
    if not inflate >= 1:
        raise DataError(f"inflate must be >= 1, got {inflate}")
    dens = {no_fault: UniformMeanGaussian(nominal.mean(0), nominal.mean(0),
                                          inflate * np.maximum(nominal.std(0, ddof=1), 1e-12))}
    groups: dict[str, list[str]] = {}
    ranges: dict[str, tuple[float, float]] = {no_fault: (0.0, 0.0)}
    for fault, by_mag in faults.items():
        mags = sorted(by_mag, key=abs)
        if len(mags) < 2:
            raise DataError(f"fault {fault!r}: need features at >= 2 magnitudes, got {len(mags)}")
        stats = {}
        for m in mags:
            x = np.asarray(by_mag[m], float)
            if x.ndim != 2 or x.shape[1] != C or x.shape[0] < 2:
                raise DataError(f"fault {fault!r} magnitude {m}: features must be (N >= 2, {C}), "
                                f"got {x.shape}")
            if not np.all(np.isfinite(x)):
                raise DataError(f"fault {fault!r} magnitude {m}: features contain NaN or inf")
            stats[m] = (x.mean(0), ((x - x.mean(0)) ** 2).sum(0), x.shape[0])
        cut = abs((split or {}).get(fault, float(np.median(np.abs(mags)))))
        small = [m for m in mags if abs(m) <= cut] or mags[:1]
        large = [m for m in mags if abs(m) >= cut] or mags[-1:]
        names = []
        for label, members in (("small", small), ("large", large)):
            means = np.array([stats[m][0] for m in members])
            ss = sum(stats[m][1] for m in members)
            dof = sum(stats[m][2] - 1 for m in members)
            std = inflate * np.maximum(np.sqrt(ss / dof), 1e-12)
            h = f"{fault}:{label}"
            dens[h] = UniformMeanGaussian(means.min(0), means.max(0), std)
            ranges[h] = (float(members[0]), float(members[-1]))
            names.append(h)
        groups[fault] = names
    return MHSSPTCalibration(dens, groups, ranges)
