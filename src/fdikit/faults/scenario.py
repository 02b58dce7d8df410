"""A simulation scenario: faults, duration, time steps, initial state, inputs, controller and noise."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import DataError
from .signals import Fault

__all__ = ["PROCESS_NOISE_MODES", "Noise", "Scenario"]

#: How continuous-time process noise enters a simulation (see :class:`Noise`).
PROCESS_NOISE_MODES = ("derivative", "psd", "increment")


def _check_cov_or_var(v: Any, what: str) -> np.ndarray:
    a = np.asarray(v, dtype=float)
    if a.ndim == 0:
        a = a.reshape(1)
    if a.ndim not in (1, 2):
        raise DataError(f"{what} must be variances (k,) or a covariance (k, k), got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise DataError(f"{what} contains NaN or inf")
    if a.ndim == 1:
        bad = np.flatnonzero(a < 0)
        if bad.size:
            raise DataError(f"{what}: variance {a[bad[0]]} of channel {bad[0]} is negative")
        return a
    if a.shape[0] != a.shape[1]:
        raise DataError(f"{what} covariance must be square, got shape {a.shape}")
    if not np.allclose(a, a.T, rtol=1e-10, atol=1e-14 * max(1.0, np.abs(a).max())):
        raise DataError(f"{what} covariance is not symmetric")
    lam = np.linalg.eigvalsh(a)
    if lam.min() < -1e-10 * max(1.0, lam.max()):
        raise DataError(f"{what} covariance is not positive semidefinite "
                        f"(smallest eigenvalue {lam.min():.3g})")
    return a


def _check_snr(v: Any, what: str) -> np.ndarray:
    a = np.atleast_1d(np.asarray(v, dtype=float))
    if a.ndim != 1:
        raise DataError(f"{what} must be a scalar or one value per channel, got shape {a.shape}")
    if np.any(np.isnan(a)) or np.any(a == -np.inf):
        raise DataError(f"{what} must be finite dB values (or +inf for no noise), got {a.tolist()}")
    return a


@dataclass
class Noise:
    """Process and measurement noise of a scenario, by covariance or by signal-to-noise ratio.

    Parameters
    ----------
    process : array_like, optional
        Process-noise variances, shape (n,) (one per state), or covariance (n, n).
    measurement : array_like, optional
        Measurement-noise variances (p,) (one per output) or covariance (p, p). Measurement noise
        is white and sampled at the measurement rate: ``y[k] = y_faulty(t_k) + v[k]``.
    process_snr_db, measurement_snr_db : float or array_like, optional
        Instead of a covariance: signal-to-noise ratio in dB per state (per output), relative to
        that signal's mean-square value in a nominal (fault-free, noise-free) pass of the same
        run: ``variance = ms * 10**(-snr/10)`` (luo-et-al: 0.5 % of the mean square,
        23 dB). ``+inf`` means no noise on that channel. Noise is independent across channels.
    process_mode : {"derivative", "psd", "increment"}, optional
        How process noise ``w`` enters (default ``"derivative"`` for continuous-time and
        nonlinear models, ``"increment"`` for discrete-time linear models; ``dt`` is the
        integration step):

        * ``"derivative"``: ``x' = f(t, x, u, p) + w(t)`` where ``w`` is a random signal held
          constant over each integration step (zero-order hold), each value with the given
          covariance ``Q`` -- the ``w_i`` of luo-et-al eq. (19), as a Simulink random
          source with sample time ``dt`` makes it. It is integrated by the same scheme as the
          input (RK4 sees it as a constant input; linear models use the exact ZOH integral
          ``int_0^dt exp(A s) ds``). Its equivalent white-noise intensity is ``Q * dt``.
        * ``"psd"``: ``Q`` is the intensity (two-sided spectral density, units^2/s) of continuous
          white noise on ``x'``; after each deterministic step the increment ``sqrt(dt) L z``
          (``L L' = Q``, ``z`` standard normal) is added: Euler--Maruyama, first order in dt.
        * ``"increment"``: ``Q`` is the covariance of the increment added to the state after
          each step: ``x[k+1] = phi(x[k]) + w[k]`` (the discrete-time convention).

    Examples
    --------
    >>> from fdikit.faults import Noise
    >>> Noise(measurement=[0.004, 0.004], process_snr_db=23.0)   # luo-et-al, Sec. III-A
    Noise(process=None, measurement=[0.004, 0.004], process_snr_db=23.0, measurement_snr_db=None, \
process_mode=None)
    """

    process: Any = None
    measurement: Any = None
    process_snr_db: Any = None
    measurement_snr_db: Any = None
    process_mode: str | None = None

    def __post_init__(self) -> None:
        if self.process is not None and self.process_snr_db is not None:
            raise DataError("give process noise either as a covariance (process=) or as an SNR "
                            "(process_snr_db=), not both")
        if self.measurement is not None and self.measurement_snr_db is not None:
            raise DataError("give measurement noise either as a covariance (measurement=) or as an SNR "
                            "(measurement_snr_db=), not both")
        if self.process is not None:
            _check_cov_or_var(self.process, "process noise")
        if self.measurement is not None:
            _check_cov_or_var(self.measurement, "measurement noise")
        if self.process_snr_db is not None:
            _check_snr(self.process_snr_db, "process_snr_db")
        if self.measurement_snr_db is not None:
            _check_snr(self.measurement_snr_db, "measurement_snr_db")
        if self.process_mode is not None and self.process_mode not in PROCESS_NOISE_MODES:
            raise DataError(f"process_mode must be one of {PROCESS_NOISE_MODES}, got {self.process_mode!r}")

    @property
    def has_process(self) -> bool:
        return self.process is not None or self.process_snr_db is not None

    @property
    def has_measurement(self) -> bool:
        return self.measurement is not None or self.measurement_snr_db is not None


def _positive(v: Any, what: str) -> float:
    try:
        x = float(v)
    except (TypeError, ValueError):
        raise DataError(f"{what} must be a number, got {v!r}") from None
    if not (np.isfinite(x) and x > 0):
        raise DataError(f"{what} must be a positive finite number of seconds, got {v!r}")
    return x


def _ratio(a: float, b: float, what: str) -> int:
    """``a / b`` as an integer, or a clear error when ``a`` is not a multiple of ``b``."""
    r = a / b
    k = round(r)
    if k < 1 or abs(r - k) > 1e-9 * max(1.0, r):
        raise DataError(f"{what}: {a!r} s is not a whole multiple of {b!r} s (ratio {r:.12g})")
    return k


@dataclass
class Scenario:
    """Everything :func:`fdikit.sim.simulate` needs besides the model.

    Parameters
    ----------
    duration : float
        Simulated time (s); the time grid is ``0, dt, ..., duration``.
    dt : float, optional
        Integration step (s). Required for continuous-time and nonlinear models; a discrete-time
        linear model steps at its own ``dt`` (give ``None`` or the same value).
    sample_time : float, optional
        Measurement sample time (s), a whole multiple of ``dt`` (default ``dt``). Measurements are
        sampled every ``sample_time`` and held in between (luo-et-al, eq. (31)); a
        controller runs at this rate. ``duration`` must be a multiple of it.
    faults : sequence of Fault
    x0 : array_like, optional
        Initial state, shape (n,) for all runs or (R, n) per run id (default zeros; a nonlinear
        model may provide ``x0`` as an attribute).
    inputs : array_like or callable, optional
        Control inputs (ZOH over each integration step): a constant (m,); a trajectory on the
        integration grid (N + 1, m) (or (N, m)); per run id (R, N + 1, m); or a callable
        ``inputs(t) -> (m,)``. Default zeros. Not together with ``controller``.
    disturbances : array_like or callable, optional
        Same forms for the disturbance inputs (group ``d``) of the model.
    controller : callable, optional
        ``controller(t, y) -> u``, vectorised over runs: ``y`` (runs, p) the noisy, faulty
        measurement, returns (runs, m) or (m,). Evaluated at every measurement sample, output
        held until the next. If it has a ``reset(runs)`` method it is called before each pass.
    noise : Noise, optional
    params : mapping, optional
        Parameter overrides of a nonlinear model: floats, or arrays (R,) with one value per run id.
    name : str

    Examples
    --------
    >>> from fdikit.faults import Bias, Noise, Scenario
    >>> sc = Scenario(duration=2.0, dt=1e-3, sample_time=1e-2,
    ...               faults=[Bias("sensor:v", 0.5, start=1.0)], noise=Noise(measurement=[1e-4]))
    >>> sc.grid()
    (0.001, 10, 2000, 201)
    """

    duration: float
    dt: float | None = None
    sample_time: float | None = None
    faults: Sequence[Fault] = ()
    x0: Any = None
    inputs: Any = None
    disturbances: Any = None
    controller: Callable[[float, np.ndarray], Any] | None = None
    noise: Noise | None = None
    params: Mapping[str, Any] | None = field(default=None)
    name: str = ""

    def __post_init__(self) -> None:
        self.duration = _positive(self.duration, "Scenario duration")
        if self.dt is not None:
            self.dt = _positive(self.dt, "Scenario dt")
        if self.sample_time is not None:
            self.sample_time = _positive(self.sample_time, "Scenario sample_time")
        if isinstance(self.faults, Fault):
            self.faults = [self.faults]
        self.faults = list(self.faults)
        for i, f in enumerate(self.faults):
            if not isinstance(f, Fault):
                raise DataError(f"Scenario fault {i} is {f!r}, not a Fault (Bias, Ramp, Gain, ...)")
        if self.controller is not None:
            if not callable(self.controller):
                raise DataError(f"Scenario controller must be callable (t, y) -> u, got {self.controller!r}")
            if self.inputs is not None:
                raise DataError("give either inputs (open loop) or a controller (closed loop), not both")
        if self.noise is not None and not isinstance(self.noise, Noise):
            raise DataError(f"Scenario noise must be a Noise object, got {type(self.noise).__name__}")
        if self.params is not None and not isinstance(self.params, Mapping):
            raise DataError("Scenario params must be a mapping name -> value, "
                            f"got {type(self.params).__name__}")
        if self.dt is not None:
            self.grid()

    def grid(self, dt: float | None = None) -> tuple[float, int, int, int]:
        """The time grid: ``(dt, ratio, n_steps, n_samples)``.

        ``ratio = sample_time / dt`` integration steps per measurement, ``n_steps`` integration
        steps in ``duration`` and ``n_samples = n_steps / ratio + 1`` measurements (t = 0 included).
        ``dt`` overrides the scenario's own (a discrete model's sample time).
        """
        if dt is None:
            dt = self.dt
        if dt is None:
            raise DataError("Scenario dt is not set: a continuous-time or nonlinear model needs an "
                            "integration step")
        ts = self.sample_time if self.sample_time is not None else dt
        ratio = _ratio(ts, dt, "Scenario sample_time must be a multiple of the integration step dt")
        n_samples_m1 = _ratio(self.duration, ts, "Scenario duration must be a multiple of sample_time")
        return float(dt), ratio, n_samples_m1 * ratio, n_samples_m1 + 1
