"""Densities calibrated from simulated residual features: a small and a large hypothesis per
fault (:func:`calibrate_densities`), ranges widened to the features' rise
(:func:`extend_ranges`), standard deviations floored (:func:`floor_std`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from ...errors import DataError
from .densities import UniformMeanGaussian

__all__ = ["MHSSPTCalibration", "calibrate_densities", "extend_ranges", "floor_std"]


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

    Ng, Chen & Speyer, Section IV-E: every fault is simulated over a range of magnitudes;
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
        settled). At least two magnitudes per fault (one segment of unknown magnitude per fault:
        :func:`~fdikit.detect.mhsspt.calibrate_segments`).
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
            raise DataError(f"fault {fault!r}: need features at >= 2 magnitudes, got {len(mags)}; with "
                            f"one segment per fault at an unknown magnitude use calibrate_segments "
                            f"(fdikit.detect.calibrate_segments: a mean along the segment's direction "
                            f"and a full covariance)")
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


def extend_ranges(cal, rise: Mapping[str, Mapping[float, np.ndarray]], *,
                  split: Mapping[str, float] | None = None, path: Any = None):
    """Widen every fault hypothesis's uniform-mean range to cover its features' rise.

    ``rise[fault][magnitude]`` (W, C) are the means of the features over short windows after the
    onset of ``fault`` at ``magnitude``; each hypothesis of the pair (small: magnitudes up to the
    median, large: from the median, as :func:`~fdikit.detect.calibrate_densities`, or ``split``)
    gets ``low = min(low, min over its magnitudes' windows)`` and ``high`` likewise, per feature.
    The standard deviations are kept (they describe the noise about the settled mean, not the
    trend of the rise). Returns a new :class:`~fdikit.detect.mhsspt.MHSSPTCalibration`.

    With ``path`` (C,) (the no-fault mean), each window is first clipped per feature to the hull
    of ``path`` and the hypothesis's settled range ``[low, high]``: the range then covers the way
    the features travel from the no-fault mean to their settled values and nothing beyond it, not
    a one-sample overshoot at the onset (a wheel-speed-sum step passes straight to two residuals
    for a sample) nor the noise of a short window in a feature the fault does not move. The
    uniform-mean density is ``1 / width`` across its range, so every unit of width a hypothesis
    takes to cover a brief spike it pays for at every later sample, and a noise-widened range of a
    feature the fault leaves alone lets that hypothesis take another fault's settled features.

    Examples
    --------
    >>> from fdikit.detect.mhsspt import MHSSPTCalibration
    >>> from fdikit.detect import UniformMeanGaussian
    >>> c = MHSSPTCalibration({"none": UniformMeanGaussian([0.0], [0.0], [1.0]),
    ...                        "f:small": UniformMeanGaussian([2.0], [3.0], [1.0]),
    ...                        "f:large": UniformMeanGaussian([4.0], [5.0], [1.0])},
    ...                       {"f": ["f:small", "f:large"]}, {})
    >>> e = extend_ranges(c, {"f": {1.0: np.array([[0.5], [2.5]]), 2.0: np.array([[3.5]]),
    ...                             3.0: np.array([[6.0]])}})
    >>> [(e.densities[h].low.tolist(), e.densities[h].high.tolist()) for h in ("f:small", "f:large")]
    [([0.5], [3.5]), ([3.5], [6.0])]
    >>> e = extend_ranges(c, {"f": {1.0: np.array([[-0.5], [2.5]]), 2.0: np.array([[3.5]]),
    ...                             3.0: np.array([[6.0]])}}, path=np.array([0.0]))
    >>> [(e.densities[h].low.tolist(), e.densities[h].high.tolist()) for h in ("f:small", "f:large")]
    [([0.0], [3.0]), ([3.5], [5.0])]
    """
    dens = dict(cal.densities)
    for fault, by_mag in rise.items():
        if fault not in cal.groups:
            raise DataError(f"no hypotheses for fault {fault!r}; faults: {list(cal.groups)}")
        mags = sorted(by_mag, key=abs)
        cut = abs((split or {}).get(fault, float(np.median(np.abs(mags)))))
        small = [m for m in mags if abs(m) <= cut] or mags[:1]
        large = [m for m in mags if abs(m) >= cut] or mags[-1:]
        hyps = cal.groups[fault]
        for h, ms in zip(hyps, (small, large) if len(hyps) == 2 else (mags,)):
            x = np.concatenate([np.asarray(by_mag[m], float) for m in ms])
            if not np.all(np.isfinite(x)):
                raise DataError(f"fault {fault!r}: rise features contain NaN or inf")
            d = dens[h]
            if path is not None:
                x = np.clip(x, np.minimum(d.low, path), np.maximum(d.high, path))
            dens[h] = UniformMeanGaussian(np.minimum(d.low, x.min(0)), np.maximum(d.high, x.max(0)), d.std)
    return MHSSPTCalibration(dens, dict(cal.groups), dict(cal.ranges))


def floor_std(cal, frac: float, *, h0_floor: bool = False):
    """Floor every density's per-feature std at ``frac`` times its own upper mean ``high`` (a
    relative model error: a few per cent of a residual's level) and, with ``h0_floor``, at the
    no-fault (first) hypothesis's std (a fault adds to the noise, it does not remove it), as a new
    :class:`~fdikit.detect.mhsspt.MHSSPTCalibration`.

    Examples
    --------
    >>> from fdikit.detect.mhsspt import MHSSPTCalibration
    >>> from fdikit.detect import UniformMeanGaussian
    >>> c = MHSSPTCalibration({"none": UniformMeanGaussian([0.1], [0.1], [0.001]),
    ...                        "f": UniformMeanGaussian([1.0], [2.0], [0.01])}, {}, {})
    >>> [floor_std(c, 0.05).densities[h].std.round(6).tolist() for h in ("none", "f")]
    [[0.005], [0.1]]
    >>> floor_std(c, 0.0, h0_floor=True).densities["f"].std.tolist()
    [0.01]
    """
    h0 = next(iter(cal.densities.values())).std if h0_floor else 0.0
    # a fault does not remove the noise: no hypothesis narrower than the no-fault one (h0_floor)
    dens = {h: UniformMeanGaussian(d.low, d.high, np.maximum(np.maximum(d.std, frac * np.abs(d.high)), h0))
            for h, d in cal.densities.items()}
    return MHSSPTCalibration(dens, dict(cal.groups), dict(cal.ranges))
