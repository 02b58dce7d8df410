"""The two-mass monitor of the bad-input tests (gaps, plausibility, invalid samples): the observer
residuals of the two-mass system, a GLRT, a hold and an MHSSPT on ``r:pos2`` (:func:`build`)."""

from __future__ import annotations

import numpy as np

from fdikit.detect import GLRT, MHSSPT, Hold, UniformMeanGaussian
from fdikit.monitor import Decision, Monitor
from fdikit.residuals import ObserverResidual, design_observer_residual
from fdikit.systems import two_mass


def observer_design():
    """The two-mass observer residual design (Kalman gains for the sensor noise)."""
    return design_observer_residual(two_mass.model(), dt=two_mass.DT, Q=np.eye(4) * 1e-8,
                                    R=np.eye(2) * two_mass.NOISE_STD**2)


def build(design, decision: bool = True, **kw) -> Monitor:
    """The monitor on ``design``: GLRT (W = 10), hold (50, Z = 3), the bias MHSSPT; with a decision
    on the held alarms and ``P:bias`` at 0.9 (``decision``); ``on_invalid="hold"``, ``kw`` to
    :class:`~fdikit.monitor.Monitor`."""
    gen = ObserverResidual(design)
    glrt = GLRT(gen.output_names, 0.0, two_mass.NOISE_STD**2, W=10)
    hold = Hold(glrt.output_names, 50.0, Z=3, absolute=False)
    mh = MHSSPT(["r:pos2"], {"ok": UniformMeanGaussian([0], [0], [0.003]),
                             "bias": UniformMeanGaussian([0.004], [0.05], [0.003])}, p=1e-3, q=1e-3)
    dec = Decision([*hold.output_names, "P:bias"], level=0.9) if decision else None
    return Monitor([gen], [glrt, hold, mh], dec, on_invalid="hold", **kw)
