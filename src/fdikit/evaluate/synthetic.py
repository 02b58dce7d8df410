"""A labelled multi-fault residual data set with a known structure, for judging isolation pipelines
on data they were not written for.

:func:`labelled_residuals` generates one long record of ``channels`` residuals, sample by sample,
with what real residuals of a vehicle have and the papers' simulations do not:

* **correlated channels**: the noise innovations have a random covariance with correlation about
  ``correlation`` between channels;
* **serial correlation**: every channel is an AR(1) process with coefficient ``ar``;
* **slowly varying operating conditions**: a low-passed random walk ``o(t)`` (unit variance) moves
  every residual's mean along a fixed direction (``drift`` noise standard deviations) and scales
  the fault signatures by ``1 + scale_drift o(t)``;
* **faults of unknown size**: fault segments (class ``k`` adds ``a s_k`` to the residuals, with a
  signature ``s_k`` of unit norm in noise units and a magnitude ``a`` drawn per segment in
  ``magnitude``) alternate with nominal segments of random lengths; some signature pairs are close
  (cosine about ``similar``) so that isolation is not trivial.

Labels are per sample: ``"nominal"`` or the fault's name. The split for training and testing
should be time ordered (:func:`time_split`), as it is with real logs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import lfilter

from ..errors import DataError

__all__ = ["LabelledResiduals", "labelled_residuals", "time_split"]


@dataclass
class LabelledResiduals:
    """A generated record: residuals ``r`` (T, C), labels (T,), the operating condition (T,),
    sample time ``dt`` (s), the fault signatures (K, C) and the segment table."""

    r: np.ndarray
    labels: np.ndarray
    condition: np.ndarray
    dt: float
    faults: list[str]
    signatures: np.ndarray
    segments: list[tuple[int, int, str, float]]

    @property
    def channels(self) -> list[str]:
        return [f"r{j}" for j in range(self.r.shape[1])]


def labelled_residuals(n_samples: int = 200_000, *, channels: int = 12, faults: int = 7, dt: float = 0.01,
                       ar: float = 0.8, correlation: float = 0.5, drift: float = 0.5,
                       scale_drift: float = 0.3,
                       magnitude: tuple[float, float] = (0.6, 2.0), similar: float = 0.8,
                       segment: tuple[int, int] = (300, 1500), nominal_share: float = 0.5,
                       seed: int = 0) -> LabelledResiduals:
    """One long labelled record (see the module docstring).

    Parameters
    ----------
    n_samples : int
        Record length (samples).
    channels, faults : int
        Residual channels ``C`` and fault classes ``K`` (named ``F1`` ... ``FK``).
    dt : float
        Sample time (s), for reporting rates per unit of time.
    ar : float
        AR(1) coefficient of every channel's noise (0 <= ar < 1).
    correlation : float
        Typical correlation between the channels' innovations (0 <= correlation < 1).
    drift, scale_drift : float
        Operating-condition effect on the residual mean (noise standard deviations per unit of the
        condition) and on the signatures' scale.
    magnitude : (float, float)
        Range of the per-segment fault magnitude, in stationary noise standard deviations times the
        signature's unit norm.
    similar : float
        Cosine between the signatures of fault pairs (F1, F2), (F3, F4), ...
    segment : (int, int)
        Range of segment lengths (samples).
    nominal_share : float
        Fraction of segments that are nominal.
    seed : int

    Returns
    -------
    LabelledResiduals

    Examples
    --------
    >>> d = labelled_residuals(5000, channels=4, faults=3, seed=1)
    >>> d.r.shape, sorted(set(d.labels.tolist()))
    ((5000, 4), ['F1', 'F2', 'F3', 'nominal'])
    """
    if n_samples < 1000 or channels < 2 or faults < 1:
        raise DataError(f"need n_samples >= 1000, channels >= 2, faults >= 1; got {n_samples}, {channels}, "
                        f"{faults}")
    if not (0 <= ar < 1 and 0 <= correlation < 1 and 0 <= nominal_share < 1):
        raise DataError(f"ar, correlation and nominal_share must lie in [0, 1); got {ar}, {correlation}, "
                        f"{nominal_share}")
    if not (0 < magnitude[0] <= magnitude[1]) or not (1 <= segment[0] <= segment[1]):
        raise DataError(f"bad magnitude {magnitude} or segment {segment} range")
    rng = np.random.default_rng(seed)
    C, K, T = int(channels), int(faults), int(n_samples)
    # innovations: equicorrelated plus a random perturbation, scaled to unit stationary variance
    L = rng.normal(size=(C, C)) * 0.3
    S = (1 - correlation) * np.eye(C) + correlation * np.ones((C, C)) + L @ L.T / C
    d = np.sqrt(np.diag(S))
    S = S / np.outer(d, d)
    chol = np.linalg.cholesky(S)
    innov = rng.normal(size=(T, C)) @ chol.T * np.sqrt(1 - ar * ar)
    e0 = rng.normal(size=C) @ chol.T
    e = lfilter([1.0], [1.0, -ar], innov, axis=0, zi=(ar * e0)[None, :])[0]
    # slowly varying operating condition (low-passed random walk, unit variance)
    w = np.cumsum(rng.normal(size=T)) * 0.02
    a = np.exp(-1.0 / 3000.0)
    o = lfilter([1 - a], [1.0, -a], w, zi=[a * w[0]])[0]
    o = (o - o.mean()) / (o.std() + 1e-12)
    g = rng.normal(size=C)
    g /= np.linalg.norm(g)
    # signatures: unit norm in the metric of the stationary noise covariance; pairs made similar
    sig = rng.normal(size=(K, C))
    for i in range(0, K - 1, 2):
        u = sig[i] / np.linalg.norm(sig[i])
        v = sig[i + 1] - (sig[i + 1] @ u) * u
        v /= np.linalg.norm(v)
        sig[i + 1] = similar * u + np.sqrt(1 - similar**2) * v
    Si = np.linalg.inv(S)
    sig = sig / np.sqrt(np.einsum("kc,cd,kd->k", sig, Si, sig))[:, None] * 2.0
    names = [f"F{k + 1}" for k in range(K)]
    labels = np.empty(T, dtype=object)
    r = e + drift * o[:, None] * g[None, :]
    segs: list[tuple[int, int, str, float]] = []
    k0 = 0
    while k0 < T:
        n = int(rng.integers(segment[0], segment[1] + 1))
        k1 = min(T, k0 + n)
        if rng.random() < nominal_share:
            labels[k0:k1] = "nominal"
            segs.append((k0, k1, "nominal", 0.0))
        else:
            f = int(rng.integers(K))
            m = float(rng.uniform(*magnitude))
            r[k0:k1] += m * (1 + scale_drift * o[k0:k1, None]) * sig[f][None, :] / 2.0
            labels[k0:k1] = names[f]
            segs.append((k0, k1, names[f], m))
        k0 = k1
    return LabelledResiduals(r, labels.astype(str), o, float(dt), names, sig / 2.0, segs)


def time_split(n: int, train: float = 0.6) -> tuple[slice, slice]:
    """The time-ordered split: the first ``train`` fraction of a record, then the rest."""
    if not 0 < train < 1:
        raise DataError(f"train fraction must lie in (0, 1), got {train}")
    k = round(n * train)
    return slice(0, k), slice(k, n)
