"""The experiments of ng-chen-speyer, Section V, as named scenarios of the car health monitor.

Each scenario simulates the automated car (:func:`~fdikit.systems.car.simulate_drive`,
with sensor noise), runs the calibrated longitudinal or lateral monitor
(:func:`~fdikit.systems.car.monitor.calibrate_monitor`) in batch, and summarises the
detection time, the isolated fault, the peak probability of every hypothesis and the false
announcements; :func:`plot_scenario` draws the residual norms and the probabilities (paper Figs.
4-7).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ...errors import DataError
from ...faults import Bias, Intermittent
from .driving import simulate_drive
from .monitor import calibrate_monitor, car_signals, sensor_noise

__all__ = ["SCENARIOS", "SENSOR_STAGES_DEFAULT", "CarScenario", "demo_summary", "plot_scenario",
           "run_scenario"]


@dataclass(frozen=True)
class CarScenario:
    """One experiment: drive, fault and the monitor block that should see it."""

    description: str
    block: str
    kind: str
    speed: float
    duration: float
    fault: str  # monitored fault name (MHSSPT group)
    target: str  # injected fault target
    magnitude: float
    onset: float
    windows: tuple[tuple[float, float], ...] = ()
    fast_accelerometer: bool = False
    q: float = 0.0
    extra: dict[str, Any] = field(default_factory=dict)


#: Named scenarios (ng-chen-speyer, Section V). Onsets are the paper's where it gives them.
SCENARIOS: dict[str, CarScenario] = {
    "accel_bias_0.4": CarScenario("longitudinal accelerometer bias 0.4 m/s^2 (Fig. 4)", "longitudinal",
                                  "curve", 20.0, 12.0, "accelerometer", "sensor:a_x", 0.4, 8.0),
    "accel_bias_0.6": CarScenario("longitudinal accelerometer bias 0.6 m/s^2 (Fig. 4)", "longitudinal",
                                  "curve", 20.0, 12.0, "accelerometer", "sensor:a_x", 0.6, 8.0),
    "accel_bias_0.8": CarScenario("longitudinal accelerometer bias 0.8 m/s^2 (Fig. 4)", "longitudinal",
                                  "curve", 20.0, 12.0, "accelerometer", "sensor:a_x", 0.8, 8.0),
    "accel_bias_0.6_fast": CarScenario("accelerometer bias 0.6 m/s^2, re-tuned filter: 100x Riccati "
                                       "state weight (Fig. 4, second column)", "longitudinal", "curve", 20.0,
                                       12.0, "accelerometer", "sensor:a_x", 0.6, 8.0,
                                       fast_accelerometer=True),
    "brake_actuator": CarScenario("driver presses the brake at 23 s, 24 m/s on the curve (Fig. 5)",
                                  "longitudinal", "curve", 24.0, 26.0, "brake_actuator", "actuator:brake",
                                  0.5, 23.0),
    "brake_actuator_short": CarScenario("driver presses the brake at 7 s, 24 m/s on the curve (Fig. 5, "
                                        "shortened)", "longitudinal", "curve", 24.0, 9.0, "brake_actuator",
                                        "actuator:brake", 0.5, 7.0),
    "steering_actuator": CarScenario("driver turns the wheel at 3 s, 20 m/s on the curve (Fig. 6)", "lateral",
                                     "curve", 20.0, 6.0, "steering_actuator", "actuator:steer", 0.015, 3.0),
    "intermittent_front_wheel": CarScenario(
        "intermittent front wheel-speed sensor fault from 28 s (Fig. 7)", "lateral", "curve", 20.0, 34.0,
        "front_wheel_diff", "sensor:w_front_diff", 0.6, 28.0,
        windows=((28.0, 29.0), (30.0, 30.6), (31.5, 32.5), (33.0, 33.4)), q=0.05),
}


def _first(mask: np.ndarray) -> int | None:
    i = np.flatnonzero(mask)
    return int(i[0]) if i.size else None


#: Whether :func:`run_scenario` adds the sensor stages (issue 27) to each block by default: on where
#: they leave the paper's scenarios' announcements unchanged. Longitudinal (speed group): the four
#: accelerometer and two brake-actuator scenarios announce exactly as without (probabilities bitwise
#: equal). Lateral (yaw group): opt-in, as it changes the intermittent front-wheel scenario's
#: announcements: without, two episodes (``front_wheel_diff`` at 28.04 s and again at 30.04 s); with,
#: one episode (28.04 s) revised to ``front_wheel_diff:drift`` at 28.07 s and to
#: ``front_wheel_diff:intermittent`` at 30.07 s (the steering scenario is unchanged).
SENSOR_STAGES_DEFAULT: dict[str, bool] = {"longitudinal": True, "lateral": False}


def run_scenario(name: str, *, seed: int = 1, progress: bool = False,
                 sensor_stages: bool | None = None) -> dict[str, Any]:
    """Run a named scenario.

    ``progress`` shows its steps (design and calibration, simulation, monitor) on standard
    error; the numbers do not depend on it. ``sensor_stages`` adds the peer checks of
    the block's redundant group and the fault-type stage
    (:func:`~fdikit.systems.car.monitor.with_peer_checks`, designed on
    :func:`~fdikit.systems.car.monitor.nominal_drives` at the scenario's speed; issue 27): their
    announcements ``"<sensor>:<type>"`` are in ``summary["sensor_faults"]`` and in ``events``; the
    MHSSPT's probabilities are unchanged bitwise, and on the paper's scenarios so are its
    announcements (the summary's ``isolated`` and ``false_announcements`` count every announcement).
    Default (None): :data:`SENSOR_STAGES_DEFAULT` of the scenario's block.

    Returns
    -------
    dict
        ``summary`` (JSON-able: detection time and delay, isolated fault, peak probability of
        every fault, false announcements, for intermittent faults the per-window times) and
        ``signals`` (``t``, ``features`` Signals, ``probabilities`` Signals, ``inputs``,
        ``measurements``, ``events``: the monitor's announcements) for plotting and reports.

    Examples
    --------
    >>> out = run_scenario("steering_actuator")                 # doctest: +SKIP
    >>> out["summary"]["isolated"]                              # doctest: +SKIP
    'steering_actuator'
    """
    if name not in SCENARIOS:
        raise DataError(f"unknown scenario {name!r}; scenarios: {sorted(SCENARIOS)}")
    from ...report.progress import progress_steps

    sc = SCENARIOS[name]
    if sensor_stages is None:
        sensor_stages = SENSOR_STAGES_DEFAULT[sc.block]
    t0 = time.perf_counter()
    with progress_steps(progress, 3, f"car scenario {name}") as steps:
        steps.step(f"design and calibrate the {sc.block} monitor at {sc.speed:g} m/s")
        mon = calibrate_monitor(sc.block, sc.speed, fast_accelerometer=sc.fast_accelerometer, q=sc.q)
        if sensor_stages:
            from .monitor import nominal_drives, with_peer_checks

            mon = with_peer_checks(mon, nominal_drives(sc.speed))
        t_cal = time.perf_counter() - t0
        if sc.windows:
            fault = Intermittent(sc.target, sc.magnitude, windows=list(sc.windows), start=sc.onset)
        else:
            fault = Bias(sc.target, sc.magnitude, start=sc.onset)
        steps.step(f"simulate {sc.duration:g} s of driving with the fault")
        res = simulate_drive(sc.kind, sc.speed, duration=sc.duration, faults=[fault], seed=seed, dt=2.5e-3,
                             noise=sensor_noise())
        sig = car_signals(res)
        steps.step("run the monitor")
        out = mon.run(sig)
    t = sig.t
    P = out.statistics
    probs = {f: P[f"P:{f}"][0] for f in mon.faults}
    feats = out.statistics.select(mon.features)
    level = mon.monitor.decision.level
    k_on = _first(probs[sc.fault] >= level)
    first = out.first_event(0)
    wrong = [e for e in out.events if e.hypothesis != sc.fault or e.t < sc.onset]
    before = t < sc.onset
    summary: dict[str, Any] = {
        "name": name, "description": sc.description, "block": sc.block, "fault": sc.fault,
        "injected": {"target": sc.target, "magnitude": sc.magnitude, "onset_s": sc.onset},
        "detection_time_s": None if k_on is None else round(float(t[k_on]), 3),
        "detection_delay_s": None if k_on is None else round(float(t[k_on] - sc.onset), 3),
        "isolated": first.hypothesis if first is not None else None,
        "peak_probability": {f: round(float(p.max()), 4) for f, p in probs.items()},
        "peak_probability_before_onset": {f: round(float(p[before].max()), 4) for f, p in probs.items()},
        "max_wrong_probability_after_onset": round(float(max(
            (p[~before].max() for f, p in probs.items() if f != sc.fault), default=0.0)), 4),
        "false_announcements": [{"t": round(e.t, 3), "hypothesis": e.hypothesis} for e in wrong],
        "announcement_level": level,
        "throttle_before_deg": round(float(res.u["throttle"][0][before].mean()), 3),
        "throttle_end_deg": round(float(res.u["throttle"][0][-1]), 3),
        "calibration_s": round(t_cal, 2), "seconds": round(time.perf_counter() - t0, 2),
        "sensor_faults": [{"t": round(e.t, 3), "hypothesis": e.hypothesis, "kind": e.kind}
                          for e in sorted([*out.events, *getattr(out, "changes", [])], key=lambda e: e.k)
                          if ":" in e.hypothesis] if sensor_stages else None,
    }
    if sc.windows:
        p = probs[sc.fault]
        per = []
        for on, off in sc.windows:
            k1 = _first((t >= on) & (p >= 0.9))
            k2 = _first((t >= off) & (p <= 0.1))
            per.append({"on_s": on, "off_s": off,
                        "rise_delay_s": None if k1 is None or t[k1] >= off else round(float(t[k1] - on), 3),
                        "fall_delay_s": None if k2 is None else round(float(t[k2] - off), 3)})
        summary["windows"] = per
    return {"summary": summary, "t": t, "features": feats,
            "probabilities": P.select([f"P:{f}" for f in mon.faults]), "inputs": res.u, "measurements": res.y,
            "events": list(out.events)}


#: Measurements shown beside the commands, per monitor block (paper Figs. 5-7, third column).
_SHOWN = {"longitudinal": ("w_engine", "a_x"), "lateral": ("yaw_rate", "w_front_diff")}


def plot_scenario(out: dict[str, Any], path: str | None = None):
    """Figure of a scenario as paper Figs. 4-7: residual norms (left), probabilities (middle),
    commands and measurements (right).

    Each residual norm has its own panel, divided by its largest fault-free value (99th
    percentile before the onset), so 1 is "as large as it gets without the fault" and no
    residual swamps another. The fault's onset (and, for an intermittent fault, its windows) is
    shaded, the monitor's announcements are marked (dotted red lines) and the announcement
    level is drawn on the probabilities. The brake panel shows the brake *command*, which is
    what the monitor reads (0 on the curve: the automated driver does not brake), and the
    *measured* brake pressure, which shows what the driver's foot did (the actuator fault).

    Saved to ``path`` (any matplotlib format) when given; returns the path, or the figure when
    ``path`` is None.
    """

    from ...report.figures import normalise, panel_figure, save

    s = out["summary"]
    t = out["t"]
    onset = s["injected"]["onset_s"]
    before = t < onset
    sc = SCENARIOS.get(s["name"])
    F = out["features"]
    res_panels = []
    for j, n in enumerate(F.names):
        y, scale = normalise(F.values[0, :, j], before)
        res_panels.append({"title": f"{n} (x {scale:.3g})", "ylabel": "norm / fault-free", "unit": "–",
                           "traces": [(n.strip("|"), y)], "legend": False})
    P = out["probabilities"]
    level = s.get("announcement_level", 0.5)
    faulty = f"P:{s['fault']}"
    others = [n for n in P.names if n != faulty]
    prob_panels = [{"title": f"probability of the injected fault ({s['fault']})", "ylabel": "probability",
                    "unit": "–", "ylim": (-0.05, 1.05), "thresholds": [("announce", level)],
                    "traces": [(faulty, P[faulty][0])]},
                   {"title": "probabilities of the other faults", "ylabel": "probability", "unit": "–",
                    "ylim": (-0.05, 1.05), "thresholds": [("announce", level)],
                    "traces": [(n, P[n][0]) for n in others]}]
    U, Y = out["inputs"], out["measurements"]
    cmd_panels = [{"title": "throttle command", "ylabel": "throttle", "unit": U.units[U.index("throttle")[0]],
                   "traces": [("throttle command", U["throttle"][0])], "legend": False}]
    brake = [("brake command (monitor input)", U["brake"][0], {"lw": 1.4})]
    if "brake_meas" in Y:
        brake.append(("brake pressure measured", Y["brake_meas"][0], {"lw": 0.8}))
    cmd_panels.append({"title": "brake: command vs measured pressure", "ylabel": "brake pressure",
                       "unit": U.units[U.index("brake")[0]], "traces": brake})
    cmd_panels.append({"title": "steering command", "ylabel": "road-wheel angle",
                       "unit": U.units[U.index("steer")[0]], "traces": [("steer command", U["steer"][0])],
                       "legend": False})
    for m in _SHOWN.get(s.get("block", ""), ()):
        if m in Y:
            cmd_panels.append({"title": f"measured {m}", "ylabel": m, "unit": Y.units[Y.index(m)[0]],
                               "traces": [(m, Y[m][0])], "legend": False})
    shade = [(a, b, "fault") for a, b in sc.windows] if sc is not None and sc.windows else \
        [(onset, float(t[-1]), "fault")]
    events = [(e.t, e.hypothesis) for e in out.get("events", [])]
    fig = panel_figure(t, [res_panels, prob_panels, cmd_panels], title=s["description"], events=events,
                       shade=shade, panel_size=(5.0, 1.45))
    if path is None:
        return fig
    return save(fig, path)


def nominal_drive(minutes: float = 10.0, *, speeds=(20.0, 24.0), kinds=("straight", "speed_change", "curve"),
                  seed: int = 7, max_run: float = 40.0, sensor_stages: bool = False,
                  **cal_kw) -> dict[str, Any]:
    """False announcements over a long fault-free drive (issue 8, item 7).

    The drive is split equally over the scenarios' speed profiles (``kinds`` x ``speeds``: straight,
    speed steps of +4 m/s, the sloped curve; 20 and 24 m/s), each simulated with sensor noise as
    runs of at most ``max_run`` s (the curved track of
    :func:`~fdikit.systems.car.driving.driving_scenario` is a 100 m straight and a half
    circle of radius 300 m: about 52 s at 20 m/s) and run through both calibrated monitors of its
    speed (``cal_kw`` to :func:`calibrate_monitor`). ``sensor_stages`` adds the peer checks and the
    fault-type stage to both (:func:`~fdikit.systems.car.monitor.with_peer_checks`; opt-in here: the
    ten minutes with them were not measured, see issue 27 item 7).

    Returns
    -------
    dict
        ``segments`` (kind, speed, seconds, announcements, largest probability of any fault per
        block), ``false_announcements`` (total), ``max_fault_probability`` (largest over all),
        ``simulated_s``.
    """
    per = 60.0 * minutes / (len(speeds) * len(kinds))
    segs, total, worst = [], 0, 0.0
    for speed in speeds:
        mons = [calibrate_monitor(b, speed, **cal_kw) for b in ("longitudinal", "lateral")]
        if sensor_stages:
            from .monitor import nominal_drives, with_peer_checks

            mons = [with_peer_checks(m, nominal_drives(speed)) for m in mons]
        for kind in kinds:
            # the curved track is a half circle after a 100 m straight: split every segment into
            # runs of at most `max_run` s (vectorised, independent noise) so that no run leaves it
            n = int(np.ceil(per / max_run))
            dur = round(per / n, 2)  # a whole number of 10 ms samples
            res = simulate_drive(kind, speed, duration=dur, runs=n, seed=seed, dt=2.5e-3,
                                 noise=sensor_noise())
            sig = car_signals(res)
            seg = {"kind": kind, "speed": speed, "seconds": dur * n, "runs": n, "announcements": [],
                   "max_probability": {}}
            for m in mons:
                out = m.run(sig)
                seg["announcements"] += [{"run": e.run, "t": round(e.t, 2), "hypothesis": e.hypothesis}
                                         for e in out.events]
                pmax = {f: float(out.statistics[f"P:{f}"].max()) for f in m.faults}
                f_top = max(pmax, key=pmax.get)
                seg["max_probability"][m.block] = {"fault": f_top, "p": round(pmax[f_top], 5)}
                worst = max(worst, pmax[f_top])
            total += len(seg["announcements"])
            segs.append(seg)
    return {"segments": segs, "false_announcements": total, "max_fault_probability": round(worst, 5),
            "simulated_s": round(sum(g["seconds"] for g in segs), 2)}


def demo_summary(details: dict | None = None) -> dict:
    """Short showcase for ``fdikit demo``: the brake-actuator scenario (paper Fig. 5), shortened.

    ``details``, when given, receives what :func:`run_scenario` returns (``summary``, ``t``,
    ``features``, ``probabilities``, ``inputs``, ``measurements``, ``events``), for the demo's report.
    """
    t0 = time.perf_counter()
    # without the sensor stages (issue 27): the same announcements, and the demo stays short (their
    # design drives took the section from 58 s to 170 s on a loaded 2-core machine)
    out = run_scenario("brake_actuator_short", sensor_stages=False)
    if details is not None:
        details.update(out)
    s = out["summary"]
    return {"scenario": s["description"], "detection_delay_s": s["detection_delay_s"],
            "isolated": s["isolated"], "false_announcements": s["false_announcements"],
            "seconds": round(time.perf_counter() - t0, 2)}
