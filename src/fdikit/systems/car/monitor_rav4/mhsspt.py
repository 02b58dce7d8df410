"""The RAV4 monitor's residual processor: its features, the MHSSPT densities calibrated on real
data (:func:`real_densities`) and the MHSSPT itself (:class:`Rav4MHSSPT`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numba import njit

from ....detect.features import FeatureNorms
from ....detect.mhsspt import (
    UniformMeanGaussian,
    WarmupMHSSPT,
    mhsspt_update,
    table_direct,
    umg_component_logpdf,
)
from ....errors import DataError

__all__ = ["MHSSPT_TABLE", "Rav4FeatureNorms", "Rav4MHSSPT", "real_densities"]


#: The RAV4 monitor's features are the core :class:`~fdikit.detect.FeatureNorms` (saveable and
#: checkpointable); the name stays for artifacts that recorded it.
Rav4FeatureNorms = FeatureNorms


@njit(cache=True)
def _serial_step(x, low, high, std, point, logw, logF, log1mp, logp_pi, logq, log1mq,
                 out):  # pragma: no cover - compiled
    """One sample of the MHSSPT for every run, serially: x (R, C) -> log posteriors out (R, H).

    The same compiled component density and recursion step as the batch kernels of
    :mod:`fdikit.detect.mhsspt` (:func:`~fdikit.detect.mhsspt.umg_component_logpdf`,
    :func:`~fdikit.detect.mhsspt.mhsspt_update`), summed in the same order, without their
    parallel launch (which costs more than the arithmetic of one sample)."""
    R, C = x.shape
    H = low.shape[0]
    ll = np.empty(H)
    phi = np.empty(H)
    P = np.empty(H)
    for r in range(R):
        for j in range(H):
            acc = 0.0
            for c in range(C):
                acc += umg_component_logpdf(x[r, c], low[j, c], high[j, c], std[j, c], point[j, c],
                                            logw[j, c])
            ll[j] = acc
        lf = logF[r]
        mhsspt_update(lf, ll, phi, P, 0, H, log1mp, logp_pi, logq, log1mq)
        for j in range(H):
            out[r, j] = lf[j]


#: The RAV4 test's densities: cubic Hermite tables of spacing 1/16 of each feature's smallest std
#: (``MHSSPT(tabulate=..., interpolation="cubic")``): 9e-9 nats from the exact densities on the
#: designed test, posteriors within 7e-7 of the exact test's and the same events on the real
#: minute and on the fleet benchmark's logs, at an eighth of the exact formula's cost (two erfc
#: and a log per component and sample were a third of a fleet task's monitor time).
MHSSPT_TABLE = 1.0 / 16.0


class Rav4MHSSPT(WarmupMHSSPT):
    """:class:`~fdikit.detect.WarmupMHSSPT` for the RAV4 monitor: its warm-up features are the
    middle of the no-fault range, and one streaming sample runs a serial compiled kernel (the same
    arithmetic as the batch path, without the parallel launch). A tabulated test (``tabulate``,
    ``interpolation``; the design uses cubic tables, :data:`MHSSPT_TABLE`) runs the fused
    table kernel of :class:`~fdikit.detect.MHSSPT` in batch and streaming alike.

    Examples
    --------
    >>> t = Rav4MHSSPT(["r"], {"none": UniformMeanGaussian([0], [0], [1]),
    ...                        "bias": UniformMeanGaussian([2], [4], [1])}, p=1e-3, warmup=5)
    >>> Rav4MHSSPT.from_dict(t.to_dict()).warmup
    5
    """

    def __init__(self, *args, **kw):
        super().__init__(*args, **kw)
        d0 = self.densities[0]
        # warm-up features: the middle of the no-fault range (its most likely mean)
        self._x0 = 0.5 * (np.asarray(d0.low, float) + np.asarray(d0.high, float))

    @table_direct  # with a table it is the base recursion (WarmupMHSSPT's)
    def _advance(self, x):
        needed = ("_umg", "_logF", "_log1mp", "_logp_pi", "_logq", "_log1mq")
        if x.shape[1] != 1 or any(getattr(self, a, None) is None for a in needed) or \
                getattr(self, "_table", None) is not None:
            return super()._advance(x)
        # streaming: one sample, the serial kernel (same arithmetic as the batch path)
        if self.warmup - (self._k - self._warm_from) > 0:  # (the warm-up restarts after a gap: resume)
            x = np.broadcast_to(self._x0, x.shape)
        x0 = np.ascontiguousarray(x[:, 0], dtype=float)
        if not np.all(np.isfinite(x0)):
            run, c = np.argwhere(~np.isfinite(x0))[0]
            raise DataError(f"MHSSPT input {self.input_names[c]!r} is not finite at sample {self._k} "
                            f"(run {run})")
        if x0.shape[0] != self._logF.shape[0]:
            raise DataError(f"sample has {x0.shape[0]} runs; the test was reset for {self._logF.shape[0]}")
        out = np.empty((x0.shape[0], 1, len(self.hypotheses)))
        _serial_step(x0, *self._umg, self._logF, self._log1mp, self._logp_pi, self._logq, self._log1mq,
                     out[:, 0])
        self._k += 1
        return out

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Rav4MHSSPT:
        dens = {h: UniformMeanGaussian(v["low"], v["high"], v["std"]) for h, v in d["densities"].items()}
        return cls(d["inputs"], dens, d["p"], d["pi"], d["q"], d["groups"], warmup=d["warmup"],
                   tabulate=d.get("tabulate"), interpolation=d.get("interpolation", "linear"))


def _local_means(x: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Moving averages over ``n`` samples of x (N, C) and the deviations of x from them."""
    if x.shape[0] < 2 * n:
        raise DataError(f"density calibration needs at least {2 * n} samples per case, got {x.shape[0]}")
    c = np.cumsum(np.vstack([np.zeros((1, x.shape[1])), x]), axis=0)
    local = (c[n:] - c[:-n]) / n                          # (N - n + 1, C)
    return local, x[n - 1:] - local


def real_densities(nominal: np.ndarray, faults: dict[str, dict[float, np.ndarray]], dt: float, window: float,
                   *, inflate: float = 1.0, no_fault: str = "none") -> dict[str, Any]:
    """Uniform-mean Gaussian densities (ng-chen-speyer, Section IV-E) calibrated on REAL data.

    On a real road a feature's level is not one number per hypothesis: it moves with the
    surface and the manoeuvre. Every hypothesis (H0 from the no-fault features; each fault's
    small and large hypotheses from the features with the fault injected at the magnitudes at
    or below / at or above its median magnitude) gets, per feature, the range ``[a, b]`` spanned
    by the features' local means (moving averages over ``window`` s) as the range of its
    uniformly distributed mean, and the spread about the local mean (times ``inflate``) as its
    standard deviation.

    Parameters
    ----------
    nominal : array (N, C)
    faults : mapping fault -> mapping magnitude -> array (N_m, C)
    dt, window : float
        Sample time and local-mean window (s).

    Returns
    -------
    dict
        ``{"densities": {hypothesis: UniformMeanGaussian}, "groups": {fault: [small, large]}}``;
        the first density is H0 (named ``no_fault``).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> nom = 1.0 + 0.1 * rng.standard_normal((400, 1)) + np.linspace(0, 0.5, 400)[:, None]
    >>> d = real_densities(nom, {"f": {m: m + nom for m in (1.0, 2.0, 3.0, 4.0)}}, 0.01, 0.5)
    >>> h0 = d["densities"]["none"]
    >>> bool(1.0 < h0.low[0] < 1.1 and 1.4 < h0.high[0] < 1.5), round(float(h0.std[0]), 1)
    (True, 0.1)
    >>> float(np.round(d["densities"]["f:large"].low[0] - h0.low[0], 6))     # magnitudes 3 and 4
    3.0
    """
    n = max(1, round(window / dt))

    def fit(xs):
        loc, dev = zip(*(_local_means(np.asarray(x, float), n) for x in xs), strict=True)
        loc, dev = np.vstack(loc), np.vstack(dev)
        return UniformMeanGaussian(loc.min(0), loc.max(0), inflate * np.maximum(dev.std(0, ddof=1), 1e-12))

    h0 = fit([nominal])
    width = h0.high - h0.low

    def fault_fit(xs):
        # a fault adds to the road's variation, it does not remove it: no fault hypothesis spans a
        # narrower range of means than H0 (else it would out-score H0 on no-fault data)
        d = fit(xs)
        return UniformMeanGaussian(d.low, np.maximum(d.high, d.low + width), np.maximum(d.std, h0.std))

    dens = {no_fault: h0}
    groups: dict[str, list[str]] = {}
    for f, by in faults.items():
        mags = sorted(by, key=abs)
        if len(mags) < 2:
            raise DataError(f"fault {f!r}: need features at >= 2 magnitudes, got {len(mags)}")
        cut = float(np.median(np.abs(mags)))
        dens[f"{f}:small"] = fault_fit([by[m] for m in mags if abs(m) <= cut])
        dens[f"{f}:large"] = fault_fit([by[m] for m in mags if abs(m) >= cut])
        groups[f] = [f"{f}:small", f"{f}:large"]
    return {"densities": dens, "groups": groups}
