"""An MHSSPT from real, labelled data: full-covariance densities from labelled segments
(:func:`calibrate_segments`), the test on pre-whitened features (:class:`WhitenedMHSSPT`)
and its design from nominal records and fault segments (:func:`design_mhsspt`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ...errors import DataError
from .calibrate import MHSSPTCalibration
from .core import MHSSPT
from .densities import LineMeanGaussian

__all__ = ["WhitenedMHSSPT", "calibrate_segments", "design_mhsspt", "shrunk_covariance"]


def _segment_list(x, what: str, C: int | None) -> list[np.ndarray]:
    segs = [x] if isinstance(x, np.ndarray) and x.ndim == 2 else list(x)
    out = []
    for i, s in enumerate(segs):
        s = np.asarray(s, float)
        if s.ndim != 2 or s.shape[0] < 2 or (C is not None and s.shape[1] != C):
            raise DataError(f"{what} segment {i}: features must be (N >= 2, {C or 'C'}), got {s.shape}")
        if not np.all(np.isfinite(s)):
            k, c = np.argwhere(~np.isfinite(s))[0]
            raise DataError(f"{what} segment {i}: feature {c} is not finite at sample {k}")
        out.append(s)
    return out


def shrunk_covariance(x: np.ndarray, method: str = "ledoit_wolf") -> np.ndarray:
    """Shrinkage covariance of samples ``x`` (N, C): the correlation matrix shrunk towards the
    identity by scikit-learn's ``LedoitWolf`` or ``OAS`` (``method`` ``"ledoit_wolf"`` or
    ``"oas"``), scaled back by the sample standard deviations (unbiased, as :func:`numpy.cov`).

    Examples
    --------
    >>> x = np.random.default_rng(0).normal(size=(60, 40)) * np.arange(1, 41)
    >>> S = shrunk_covariance(x)
    >>> bool(np.allclose(np.diag(S), x.var(0, ddof=1))), bool(np.linalg.eigvalsh(S).min() > 0)
    (True, True)
    """
    from sklearn.covariance import OAS, LedoitWolf

    x = np.asarray(x, float)
    sd = x.std(0, ddof=1)
    if np.any(sd <= 0):
        raise DataError(f"feature {int(np.argmin(sd))} is constant: no covariance")
    est = {"ledoit_wolf": LedoitWolf, "oas": OAS}.get(method)
    if est is None:
        raise DataError(f"shrinkage method must be 'ledoit_wolf' or 'oas', got {method!r}")
    z = (x - x.mean(0)) / sd
    R = est(assume_centered=True).fit(z).covariance_
    R = R / np.sqrt(np.outer(np.diag(R), np.diag(R)))  # a correlation: unit diagonal
    return R * np.outer(sd, sd)


def calibrate_segments(
    nominal,
    segments: Mapping[str, Any],
    *,
    no_fault: str = "none",
    scale: tuple[float, float] = (0.5, 2.0),
    ridge: float = 1e-9,
    cov: str = "sample",
) -> MHSSPTCalibration:
    """Full-covariance densities from labelled segments of real data, one unknown magnitude each.

    The no-fault hypothesis is the Gaussian with the nominal mean and covariance. Every labelled
    fault segment (one fault at one magnitude, which need not be known, after the onset
    transient) gives one hypothesis: a :class:`LineMeanGaussian` whose mean runs along the
    segment's offset ``d = mean(segment) - mean(nominal)`` from ``scale[0] d`` to ``scale[1] d``
    (the same fault at other sizes moves the features along the same direction) with the
    covariance of the segment about its mean. A fault with several segments gets one hypothesis
    per segment (``<fault>:0``, ``<fault>:1``, ...) and a group summing them; one segment is
    named ``<fault>``. Feed whitened features (:class:`~fdikit.detect.whiten.VARWhitener`) when
    the residuals are serially correlated (:func:`design_mhsspt` does).

    Parameters
    ----------
    nominal : array (N, C) or sequence of arrays (N_i, C)
        Fault-free features.
    segments : mapping fault -> array (N, C) or sequence of arrays
        Labelled fault segments.
    no_fault : str
        Name of the no-fault hypothesis.
    scale : (float, float)
        Range of fault sizes covered, relative to each segment's own (``(1, 1)``: exactly the
        observed size, a plain Gaussian).
    ridge : float
        Added to each covariance's diagonal, relative to its mean diagonal (numerical safety).
    cov : {"sample", "ledoit_wolf", "oas", "auto"}
        Covariance estimate: the sample covariance, or a shrinkage estimate (scikit-learn's
        Ledoit-Wolf or OAS, of the correlation, towards the identity: the variances are kept) for
        many channels and few samples, where the sample covariance's small eigenvalues are too
        small and the densities overconfident; ``"auto"``: Ledoit-Wolf for a segment of fewer than
        ``10 C`` samples, else the sample covariance.

    Returns
    -------
    MHSSPTCalibration
        ``ranges`` holds ``scale`` per fault hypothesis.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> nom = rng.normal(size=(2000, 2))
    >>> cal = calibrate_segments(nom, {"f": rng.normal(size=(500, 2)) + [3.0, 1.0]})
    >>> list(cal.densities), np.round(cal.densities["f"].b, 0).tolist()
    (['none', 'f'], [6.0, 2.0])
    """
    nom = np.concatenate(_segment_list(nominal, "nominal", None))
    C = nom.shape[1]
    if nom.shape[0] < 2 * C + 2:
        raise DataError(f"{nom.shape[0]} nominal samples are too few for a {C} x {C} covariance")
    lo, hi = (float(s) for s in scale)
    if not (0 <= lo <= hi) or not np.isfinite(hi):
        raise DataError(f"scale must be 0 <= low <= high, got {scale}")

    if cov not in ("sample", "ledoit_wolf", "oas", "auto"):
        raise DataError(f"cov must be 'sample', 'ledoit_wolf', 'oas' or 'auto', got {cov!r}")

    def cov_of(x):
        method = ("ledoit_wolf" if x.shape[0] < 10 * C else "sample") if cov == "auto" else cov
        S = np.atleast_2d(np.cov(x, rowvar=False)) if method == "sample" else shrunk_covariance(x, method)
        return S + ridge * max(float(np.mean(np.diag(S))), 1e-300) * np.eye(C)

    mu0 = nom.mean(0)
    dens: dict[str, Any] = {no_fault: LineMeanGaussian(mu0, mu0, cov_of(nom))}
    groups: dict[str, list[str]] = {}
    ranges: dict[str, tuple[float, float]] = {no_fault: (0.0, 0.0)}
    for fault, segs in segments.items():
        segs = _segment_list(segs, f"fault {fault!r}", C)
        names = [str(fault)] if len(segs) == 1 else [f"{fault}:{i}" for i in range(len(segs))]
        for h, s in zip(names, segs):
            if s.shape[0] < 2 * C + 2:
                raise DataError(f"fault {fault!r}: segment of {s.shape[0]} samples is too short for a "
                                f"{C} x {C} covariance")
            d = s.mean(0) - mu0
            dens[h] = LineMeanGaussian(mu0 + lo * d, mu0 + hi * d, cov_of(s))
            ranges[h] = (lo, hi)
        groups[str(fault)] = names
    return MHSSPTCalibration(dens, groups, ranges)


class WhitenedMHSSPT(MHSSPT):
    """:class:`MHSSPT` on pre-whitened features: every sample first passes a
    :class:`~fdikit.detect.whiten.VARWhitener` (its innovations are serially uncorrelated under
    the nominal model, so multiplying their likelihoods is right), then the recursion runs with
    densities calibrated on whitened data (e.g. :class:`LineMeanGaussian`, full covariance).
    The first ``whitener.order`` samples after :meth:`reset` (the whitener's history is not full
    yet, so its output is not an innovation) are seen as the no-fault mean, as
    :class:`WarmupMHSSPT` does. Batch and streaming alike; the whitener's history is part of the
    state.

    Parameters
    ----------
    inputs : sequence of str
        Feature channels (raw, not whitened).
    densities : mapping
        As :class:`MHSSPT`, on the whitened features.
    p, pi, q, groups
        As :class:`MHSSPT`.
    whitener : VARWhitener
        Fitted on nominal data of ``inputs``.
    temperature : float
        Every log-likelihood is divided by it (> 0; 1: the plain test). A temperature above one
        discounts the evidence of each sample for what the densities do not model (densities
        estimated from few samples, runs that differ from the training run, residual serial
        correlation); fit it on held-out data with :func:`~fdikit.detect.mhsspt.fit_temperature`.

    Examples
    --------
    >>> from fdikit import Signals
    >>> from fdikit.detect.whiten import VARWhitener
    >>> w = VARWhitener(["r"], [0.0], [[[0.5]]])
    >>> t = WhitenedMHSSPT(["r"], {"none": LineMeanGaussian([0], [0], [[1]]),
    ...                            "f": LineMeanGaussian([1], [3], [[1]])}, p=1e-3, whitener=w)
    >>> x = np.r_[np.zeros(50), np.full(50, 4.0)]
    >>> P = t.run(Signals(np.arange(100.0), x, ["r"]))["P:f"][0]
    >>> bool(P[49] < 0.01), bool(P[-1] > 0.99)
    (True, True)
    """

    _state_attrs = (*MHSSPT._state_attrs, "whitener")

    def __init__(self, inputs, densities, p, pi=None, q=0.0, groups=None, *, whitener, temperature=1.0):
        super().__init__(inputs, densities, p, pi, q, groups)
        self.temperature = float(temperature)
        if not (np.isfinite(self.temperature) and self.temperature > 0):
            raise DataError(f"temperature must be positive and finite, got {temperature}")
        if list(whitener.input_names) != list(self.input_names):
            raise DataError(f"whitener inputs {whitener.input_names} differ from the test's "
                            f"{self.input_names}")
        self.whitener = whitener
        self.whitener.reset(1)

    def reset(self, runs: int = 1) -> None:
        super().reset(runs)
        if hasattr(self, "whitener"):
            self.whitener.reset(runs)

    def loglik(self, x: np.ndarray) -> np.ndarray:
        """Log densities of every hypothesis divided by :attr:`temperature`: x (..., C) -> (..., H)."""
        ll = super().loglik(x)
        return ll if getattr(self, "temperature", 1.0) == 1.0 else ll / self.temperature

    def whitened(self, x: np.ndarray) -> np.ndarray:
        """The features the densities see for a whole record ``x`` (runs, T, C) from a reset: the
        innovations, the whitening transient replaced by the no-fault mean (the whitener is reset
        and left at the end of ``x``)."""
        self.whitener.reset(x.shape[0])
        e = self.whitener.whiten(x)
        if self.whitener.order:
            e = e.copy()
            e[:, : self.whitener.order] = self._x0
        return e

    def _advance(self, x):
        e = self.whitener.whiten(x)
        n = self.whitener.order - self._k  # whitening transient: the history is not full yet
        if n > 0:
            e = e.copy()
            e[:, :n] = self._x0
        return super()._advance(e)

    @property
    def _x0(self) -> np.ndarray:
        d0 = self.densities[0]
        return np.asarray(getattr(d0, "a", getattr(d0, "low", np.zeros(len(self.input_names)))), float)

    def to_dict(self) -> dict:
        """Configuration as plain data (densities must be :class:`LineMeanGaussian`)."""
        if not all(isinstance(d, LineMeanGaussian) for d in self.densities):
            raise DataError("only WhitenedMHSSPTs with LineMeanGaussian densities can be exported")
        return {"inputs": list(self.input_names),
                "densities": {h: d.to_dict() for h, d in zip(self.hypotheses, self.densities)},
                "p": self.p, "pi": self.pi.tolist(), "q": self.q, "groups": self.groups,
                "whitener": self.whitener.to_dict(), "temperature": self.temperature}

    @classmethod
    def from_dict(cls, d: dict) -> WhitenedMHSSPT:
        from ..whiten import VARWhitener

        dens = {h: LineMeanGaussian(v["a"], v["b"], v["cov"]) for h, v in d["densities"].items()}
        return cls(d["inputs"], dens, d["p"], d["pi"], d["q"], d["groups"],
                   whitener=VARWhitener.from_dict(d["whitener"]), temperature=d.get("temperature", 1.0))


def design_mhsspt(
    inputs: Sequence[str],
    nominal,
    segments: Mapping[str, Any],
    p: float,
    *,
    whiten: bool = True,
    order: int | None = None,
    max_order: int = 10,
    scale: tuple[float, float] = (0.5, 2.0),
    q: float = 0.0,
    no_fault: str = "none",
    criterion: str = "bic",
    cov: str = "auto",
) -> WhitenedMHSSPT:
    """An MHSSPT from labelled real data: pre-whitening fitted on the nominal records, then
    full-covariance densities from one segment per fault and magnitude (:func:`calibrate_segments`).

    Parameters
    ----------
    inputs : sequence of str
        Feature channel names (C).
    nominal : array (T, C) or sequence of arrays (T_i, C)
        Fault-free records (each one contiguous record).
    segments : mapping fault -> array (N, C) or sequence of arrays
        Labelled contiguous fault segments (after the onset transient), magnitudes unknown.
    p : float
        Change probability per sample.
    whiten : bool
        Fit a :class:`~fdikit.detect.whiten.VARWhitener` (False: mean removal only; right for
        serially independent features).
    order, max_order : int
        VAR order (None: by ``criterion`` up to ``max_order``). Where the nominal samples are too
        few for a full VAR of that order (many channels), the orders they carry compete, and a
        diagonal VAR (one autoregression per channel) is fitted when not even a full VAR(1) fits
        (:meth:`~fdikit.detect.whiten.VARWhitener.fit` with ``reduce=True``; ``whitener.info``
        says what was reduced).
    criterion : {"bic", "aic"}
        Information criterion of the order.
    scale, no_fault, cov
        As :func:`calibrate_segments` (``cov="auto"``: shrinkage covariances for segments shorter
        than ten samples per channel).
    q : float
        Return probability (:class:`MHSSPT`).

    Returns
    -------
    WhitenedMHSSPT
        Its ``calibration`` attribute is the :class:`MHSSPTCalibration` used.

    Examples
    --------
    >>> from scipy.signal import lfilter
    >>> rng = np.random.default_rng(0)
    >>> ar = lambda n: lfilter([1.0], [1.0, -0.9], rng.normal(size=(n, 2)), axis=0)
    >>> t = design_mhsspt(["a", "b"], ar(20_000), {"f": ar(3000) + [4.0, -4.0]}, p=1e-4)
    >>> t.whitener.order, t.hypotheses
    (1, ['none', 'f'])
    """
    from ..whiten import VARWhitener

    C = len(inputs)
    nom = _segment_list(nominal, "nominal", C)
    if whiten:
        w = VARWhitener.fit(nom, inputs, order=order, max_order=max_order, criterion=criterion, reduce=True)
    else:
        w = VARWhitener(inputs, np.concatenate(nom).mean(0), np.zeros((0, C, C)))
    k0 = w.order  # the first samples of each record are whitening transients

    def white(seg):
        w.reset(1)
        e = w.whiten(seg[None])[0]
        return e[k0:]

    wn = [white(s) for s in nom]
    ws = {f: [white(s) for s in _segment_list(v, f"fault {f!r}", C)] for f, v in segments.items()}
    cal = calibrate_segments(wn, ws, no_fault=no_fault, scale=scale, cov=cov)
    groups = {g: m for g, m in cal.groups.items() if m != [g]}
    test = WhitenedMHSSPT(inputs, cal.densities, p, q=q, groups=groups, whitener=w)
    test.calibration = cal
    return test
