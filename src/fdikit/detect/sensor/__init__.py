"""Detectors for the sensor faults that real logs hold: stuck, drifting, scaled and intermittent.

Each is a :class:`~fdikit.base.stage.ResidualProcessor` whose output is its test statistic
*divided by its threshold*: the detector alarms where an output is ``>= 1`` (chain a
:class:`~fdikit.detect.Hold` with threshold 1 and ``absolute=False`` for a hold of ``Z`` samples).
A ``design_*`` function builds each one from nominal (fault-free) data: the nominal levels
(mean, variance) are estimated and the threshold is the level of the statistic on those data for
a target false-alarm rate (:func:`~fdikit.detect.design_threshold`; with ``pfa = 0``, the
default, just above the largest nominal value, times ``1 + margin``: what a short real record
can honestly support).

=======================  ==========================================================================
:class:`StuckDetector`   the measured signal has not moved (by more than ``tol``) since sample j,
                         while the model-expected signal moved by ``g = (max - min) / scale`` over
                         the same samples (without an expected signal: ``g`` = samples flat)
:class:`DriftDetector`   GLR of a ramp ``s (i - j + 1)`` starting from zero at an unknown sample
                         j in the window: ``g = max_j (sum tau_i r_i)^2 / (sigma^2 sum tau_i^2)``
:class:`GainDetector`    GLR of a gain: the residual proportional to the signal, ``r = theta s``
                         from sample j: ``g = max_j (sum r_i s_i)^2 / (sigma^2 sum s_i^2)``
:class:`IntermittentDetector`  bursts that come and go: episodes of ``|r - mu0| > level``
                         (ended once below ``release`` for ``gap`` samples) counted over the last
                         ``W`` samples; ``g = count / min_bursts``
=======================  ==========================================================================

Batch (:meth:`run`) and streaming (:meth:`reset` + :meth:`step`) run the same compiled kernel on
the same state, so they give identical numbers; the state is declared in ``_state_attrs``
(checkpoint and restore), and a non-finite sample is refused before any state changes.

One module per detector, each with its compiled kernel and its design function: :mod:`.stuck`,
:mod:`.drift`, :mod:`.gain`, :mod:`.intermittent`; shared by them: :mod:`.base` (plumbing, the
ring-buffer window), :mod:`.combine` (the combination over a signature) and :mod:`.calibrate`
(thresholds from nominal data). Every name of the former single module is importable from here.
"""

# the old module's private names too (tests, and the references of issue 19, import them from here)
from .base import _BLOCK, _SCALAR_BELOW, _per_channel, _ring_history, _SensorDetector, _window  # noqa: F401
from .calibrate import _dt, _nominal, _threshold  # noqa: F401
from .combine import _combine_kernel, _max_nan, _min_nan  # noqa: F401
from .drift import _STEP_BAND, DriftDetector, _ramp_kernel, _step_known, design_drift  # noqa: F401
from .gain import (  # noqa: F401
    _GAIN_LAST,
    _GAIN_MEMO_MAX,
    _GAIN_MEMO_MIN,
    GainDetector,
    _gain_kernel,
    _gain_run,
    _gain_update,
    _same,
    design_gain,
)
from .intermittent import IntermittentDetector, _burst_kernel, design_intermittent  # noqa: F401
from .stuck import StuckDetector, _stuck_kernel, design_stuck  # noqa: F401

__all__ = [
    "DriftDetector",
    "GainDetector",
    "IntermittentDetector",
    "StuckDetector",
    "design_drift",
    "design_gain",
    "design_intermittent",
    "design_stuck",
]
