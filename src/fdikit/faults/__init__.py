"""Fault signals and simulation scenarios.

Fault signals (:mod:`fdikit.faults.signals`) act on one channel named by a target string
(``"actuator:<input>"``, ``"sensor:<output>"``, ``"param:<name>"`` or a fault input declared on a
linear model) between a start and an optional end time; :class:`FaultInjector` applies them
vectorised over runs; :class:`Scenario` bundles faults, noise, time steps, inputs and a controller
for :func:`fdikit.sim.simulate`;
:func:`apply_faults` applies faults of every type to a whole recorded log.
"""

from .apply import apply_faults, resolve_channels
from .injector import FaultInjector
from .scenario import PROCESS_NOISE_MODES, Noise, Scenario
from .signals import (
    TARGET_KINDS,
    TIME_TOL,
    Bias,
    BoundFault,
    Chirp,
    Drift,
    Fault,
    Gain,
    Intermittent,
    Parametric,
    Ramp,
    Sinusoid,
    Step,
    Stuck,
    parse_target,
    per_run,
)

__all__ = [
    "PROCESS_NOISE_MODES",
    "TARGET_KINDS",
    "TIME_TOL",
    "Bias",
    "BoundFault",
    "Chirp",
    "Drift",
    "Fault",
    "FaultInjector",
    "Gain",
    "Intermittent",
    "Noise",
    "Parametric",
    "Ramp",
    "Scenario",
    "Sinusoid",
    "Step",
    "Stuck",
    "apply_faults",
    "parse_target",
    "per_run",
    "resolve_channels",
]
