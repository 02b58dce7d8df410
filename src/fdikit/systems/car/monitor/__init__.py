"""Vehicle health monitor of the passenger car (ng-chen-speyer, Ng, Chen & Speyer, Sections IV and V).

Residual generator (Section IV-B..D):

* six fault detection filter sets of two filters each, designed on the reduced linear models at
  the operating speed (:func:`~fdikit.residuals.fault_detection_filter`: the exact unknown input
  observer where it exists, else the optimal stochastic filter):

  ====  ====================================  =======================================
  set   targets                               common nuisance
  ====  ====================================  =======================================
  1     engine-speed sensor, accelerometer    nonlinearity direction, road slope
  2     front / rear wheel-speed sum sensors  nonlinearity direction, road slope
  3     brake actuator, rear wheel-speed sum  nonlinearity direction, road slope
  4     steering actuator, front wheel diff
  5     yaw-rate sensor, rear wheel diff
  6     lateral accelerometer, rear wheel diff
  ====  ====================================  =======================================

  (each filter of a set takes the other target of the set as a nuisance too). The road slope is
  an unknown disturbance of the longitudinal block (the curve of Section V is built on a slope);
  it is blocked like the nonlinearity. The lateral filters (sets 4-6) are low-gain observers
  (:data:`LATERAL_Q_WEIGHT`) that block a sensor nuisance by not reading that sensor, with their
  residuals whitened (:func:`whiten_design`); the exact UIO depends on its nuisance only, so the
  six lateral filters are five distinct ones, each blind to one lateral fault (set 6's
  accelerometer filter is set 5's yaw-rate filter and gives no feature of its own; likewise set 3's
  brake filter is set 2's front wheel-speed filter, :meth:`CarMonitorDesign.residual_groups`).
* two parity equations (Section IV-D): throttle command vs throttle measurement, brake command
  through the brake actuator model (first-order lag ``tau_b``) vs brake-pressure measurement.

Residual processor (Section IV-E): the Euclidean norm of each distinct filter's residual and the
absolute value of each parity residual (low-pass smoothed) form the feature vector of a multiple-hypothesis
Shiryayev test (:class:`~fdikit.detect.MHSSPT`) whose uniform-mean Gaussian densities are
calibrated by simulating every fault over a range of magnitudes on the nonlinear car
(:func:`calibrate_monitor`): 15 longitudinal hypotheses (no fault + small/large for throttle,
brake actuator, brake sensor, engine speed, accelerometer, front and rear wheel-speed sums) and 11
lateral ones (steering actuator, lateral accelerometer, yaw rate, front and rear wheel-speed
differences).

The manifold-pressure sensor is not monitored: the paper detects it with a nonlinear parity
equation of its reference [13], which is not reproduced here.

Layout
------
One concept per module, every name importable from this package as before the split:
:mod:`.settings` (filter sets, monitored faults, magnitudes, block settings, sensor noise),
:mod:`.design` (:func:`design_car_monitor`), :mod:`.generators` (offset filters, parity equations,
a block's generators), :mod:`.calibration` (:func:`calibrate_monitor`, :func:`build_monitor`),
:mod:`.studies` (:func:`pattern_table`, :func:`isolation_study`), :mod:`.sensor_checks`
(:class:`CarSensorChannels`, :func:`with_sensor_checks`) and :mod:`.peers` (the redundant groups,
their peer checks and fault types, :func:`with_peer_checks`; issue 27).
"""

from __future__ import annotations

from ....detect.features import FeatureNorms  # noqa: F401
from ....detect.mhsspt import WarmupMHSSPT, extend_ranges  # noqa: F401
from ....residuals.transforms import delayed_feedthrough  # noqa: F401
from .calibration import CarMonitor, build_monitor, calibrate_monitor
from .design import (  # noqa: F401
    CarMonitorDesign,
    _design_projecting_sensors,
    _same_filter,
    design_car_monitor,
)
from .generators import (  # noqa: F401
    OffsetFilter,
    ParityEquations,
    _filter_generator,
    _generators,
    _generators_and_features,
    _parity_kernel,
    _tau_b,
)
from .peers import (
    CAR_PEER_GROUPS,
    CAR_PEER_SENSORS,
    CarPeerSignals,
    design_car_peer_stages,
    nominal_drives,
    with_peer_checks,
)
from .sensor_checks import (  # noqa: F401
    CAR_SENSOR_CHANNELS,
    CarSensorChannels,
    _biquads,
    fit_car_sensor_channels,
    with_sensor_checks,
)
from .settings import (  # noqa: F401
    BLOCK_SETTINGS,
    FILTER_SETS,
    LATERAL_FAULTS,
    LATERAL_Q_WEIGHT,
    LATERAL_SETS,
    LONGITUDINAL_FAULTS,
    LONGITUDINAL_SETS,
    MAGNITUDES,
    SENSOR_NOISE_STD,
    WHITENED_BLOCKS,
    car_signals,
    sensor_noise,
)
from .studies import isolation_study, pattern_table

__all__ = [
    "BLOCK_SETTINGS",
    "CAR_PEER_GROUPS",
    "CAR_PEER_SENSORS",
    "CAR_SENSOR_CHANNELS",
    "FILTER_SETS",
    "LATERAL_FAULTS",
    "LONGITUDINAL_FAULTS",
    "MAGNITUDES",
    "SENSOR_NOISE_STD",
    "CarMonitor",
    "CarMonitorDesign",
    "CarPeerSignals",
    "CarSensorChannels",
    "OffsetFilter",
    "ParityEquations",
    "build_monitor",
    "calibrate_monitor",
    "car_signals",
    "design_car_monitor",
    "design_car_peer_stages",
    "fit_car_sensor_channels",
    "isolation_study",
    "nominal_drives",
    "pattern_table",
    "with_peer_checks",
    "with_sensor_checks",
]
