"""The fault universe F0-F5 (luo-et-al, Section III-A, Table II) and the braking manoeuvre
(:class:`Scenario`) with its noise model.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ....errors import DataError


# --------------------------------------------------------------------------------------------
# Fault universe (luo-et-al, Section III-A, Table II)
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class FaultClass:
    """One fault class: a relative change ``magnitude`` of one parameter.

    The faulty value is ``nominal · (1 + magnitude)``; ``magnitude`` lies in ``[lo, hi]``, or
    in ``[-hi, -lo] ∪ [lo, hi]`` when ``symmetric``.
    """

    name: str
    param: str | None
    lo: float
    hi: float
    symmetric: bool
    description: str

    def check(self, magnitude: float) -> None:
        """Raise :class:`DataError` if ``magnitude`` lies outside this class."""
        if self.param is None:
            if magnitude != 0.0:
                raise DataError(f"fault class {self.name} (nominal) takes no magnitude, got {magnitude}")
            return
        a = abs(magnitude) if self.symmetric else magnitude
        if not (self.lo - 1e-12 <= a <= self.hi + 1e-12):
            rng = (f"±[{self.lo:g}, {self.hi:g}]" if self.symmetric else f"[{self.lo:g}, {self.hi:g}]")
            raise DataError(f"magnitude {magnitude:g} outside fault class {self.name} "
                            f"({self.description}): allowed {rng}")

    def draw(self, rng: np.random.Generator, step: float | None = None) -> float:
        """One magnitude drawn uniformly inside the class (random sign when symmetric).

        With ``step``, drawn uniformly from the grid ``lo, lo + step, ..., hi`` instead (the
        paper's F3/F4 sizes ±2 %, ±3 %, ..., ±10 % are ``step=0.01``).
        """
        if self.param is None:
            return 0.0
        if step is None:
            m = rng.uniform(self.lo, self.hi)
        else:
            n = int(np.floor((self.hi - self.lo) / step + 1e-9))
            m = self.lo + step * rng.integers(0, n + 1)
        if self.symmetric and rng.random() < 0.5:
            m = -m
        return float(m)


#: Fault classes of Table II. Upper bounds where the paper gives only a lower one (F1.2, F2.2,
#: F5) are our choice: 10 %, 30 % and 50 %.
FAULT_CLASSES: dict[str, FaultClass] = {
    "F0": FaultClass("F0", None, 0.0, 0.0, False, "nominal"),
    "F1.1": FaultClass("F1.1", "k_ws", -0.05, -0.02, False, "wheel-speed sensor reading 2-5 % low"),
    "F1.2": FaultClass("F1.2", "k_ws", -0.10, -0.05, False, "wheel-speed sensor reading >= 5 % low"),
    "F2.1": FaultClass("F2.1", "R_w", -0.20, -0.02, False, "wheel radius R_w 2-20 % smaller"),
    "F2.2": FaultClass("F2.2", "R_w", -0.30, -0.20, False, "wheel radius R_w >= 20 % smaller"),
    "F3": FaultClass("F3", "K_f", 0.02, 0.10, True, "brake torque gain K_f ±2-10 %"),
    "F4": FaultClass("F4", "I_w", 0.02, 0.10, True, "wheel inertia I_w ±2-10 %"),
    "F5": FaultClass("F5", "tau_m", 0.15, 0.50, False, "master-cylinder time constant tau_m +15 % or more"),
}


@dataclass(frozen=True)
class Scenario:
    """A braking manoeuvre with one fault class and the noise model.

    Parameters
    ----------
    fault : str
        Key of :data:`FAULT_CLASSES` ("F0", "F1.1", ..., "F5").
    magnitude : float or None
        Relative parameter change (e.g. -0.05 for K_f -5 %). ``None`` draws one per run,
        uniformly inside the class (0 for F0).
    snr_db : float or None
        Process-noise signal-to-noise ratio (23, 20 or 17 dB in the paper); None: no process noise.
    meas_var : float
        Variance of the measurement noise on each channel, (rad/s)^2 (0.004 in the paper).
    v0 : float
        Initial vehicle speed, m/s.
    t_brake : float
        Time the driver steps on the brake, s.
    t_end : float
        Length of the record, s (12.5 s: N = 1250 samples at 10 ms).
    dt, sample_dt : float
        Integration/controller step (1 ms = t_s) and diagnostic sample interval (10 ms), s.
    v_off : float
        Vehicle speed below which the ABS switches off and the wheel may lock, m/s.
    grid_step : float or None
        When magnitudes are drawn, draw them on a grid of this step inside the class
        (0.01 gives the paper's ±2 %, ±3 %, ..., ±10 % for F3/F4); None: uniform.
    noise_hold : float or None
        Time over which one process-noise sample is held, s (a multiple of ``dt``). None (the
        default, the reading Table III supports; see the module docstring): a new sample every
        integration step of 1 ms. 0.01: one per 10 ms measurement sample (ten times the power).
    pedal : {"step", "ramp"}
        Driver's pedal-force profile. ``"step"`` (default): the step response of eq. (4) with
        ``tau_p`` (K_p reached within ~0.1 s). ``"ramp"`` (opt-in experiment): ``F_p`` rises
        linearly from 0 at ``t_brake`` to ``K_p`` at ``t_brake + pedal_ramp`` and is then held
        (no ``tau_p`` lag). The same profile drives the plant and the nominal P_m input the
        observer receives (only ``tau_m`` differs between them under F5). See the comment beside
        ``tau_p`` in :data:`PARAMS`.
    pedal_ramp : float or None
        Ramp duration T_ramp, s (> 0); required with ``pedal="ramp"``, must be None with "step".
    """

    fault: str = "F0"
    magnitude: float | None = None
    snr_db: float | None = 23.0
    meas_var: float = 0.004
    v0: float = 28.0
    t_brake: float = 0.5
    t_end: float = 12.5
    dt: float = 1e-3
    sample_dt: float = 1e-2
    v_off: float = 2.0
    grid_step: float | None = None
    noise_hold: float | None = None
    pedal: str = "step"
    pedal_ramp: float | None = None

    def __post_init__(self):
        if self.fault not in FAULT_CLASSES:
            raise DataError(f"unknown fault {self.fault!r}; known: {list(FAULT_CLASSES)}")
        if self.magnitude is not None:
            FAULT_CLASSES[self.fault].check(float(self.magnitude))
        sub = self.sample_dt / self.dt
        if self.dt <= 0 or abs(sub - round(sub)) > 1e-9 or round(sub) < 1:
            raise DataError(f"sample_dt ({self.sample_dt}) must be a positive multiple of dt ({self.dt})")
        n = self.t_end / self.sample_dt
        if abs(n - round(n)) > 1e-9 or round(n) < 1:
            raise DataError(f"t_end ({self.t_end}) must be a positive multiple of "
                            f"sample_dt ({self.sample_dt})")
        if self.meas_var < 0:
            raise DataError(f"meas_var must be >= 0, got {self.meas_var}")
        if self.noise_hold is not None:
            nh = self.noise_hold / self.dt
            if self.noise_hold <= 0 or abs(nh - round(nh)) > 1e-9:
                raise DataError(f"noise_hold ({self.noise_hold} s) must be a positive multiple of dt "
                                f"({self.dt} s)")
        if self.pedal not in ("step", "ramp"):
            raise DataError(f"pedal must be 'step' or 'ramp', got {self.pedal!r}")
        if self.pedal == "ramp" and (self.pedal_ramp is None or not self.pedal_ramp > 0):
            raise DataError(f"pedal='ramp' needs pedal_ramp > 0 s, got {self.pedal_ramp}")
        if self.pedal == "step" and self.pedal_ramp is not None:
            raise DataError(f"pedal_ramp ({self.pedal_ramp} s) is only used with pedal='ramp'")
        if self.v0 <= self.v_off:
            raise DataError(f"initial speed v0 = {self.v0} m/s must exceed v_off = {self.v_off} m/s")

    @property
    def n_steps(self) -> int:
        return round(self.t_end / self.dt)

    @property
    def n_samples(self) -> int:
        return round(self.t_end / self.sample_dt)

    @property
    def substeps(self) -> int:
        return round(self.sample_dt / self.dt)

    @property
    def ramp_time(self) -> float:
        """Pedal ramp duration, s, as the kernel takes it (0.0: the step of eq. (4))."""
        return float(self.pedal_ramp) if self.pedal == "ramp" else 0.0

    @property
    def noise_hold_steps(self) -> int:
        """Integration steps over which one process-noise sample is held (1: a new one every step)."""
        return 1 if self.noise_hold is None else round(self.noise_hold / self.dt)
