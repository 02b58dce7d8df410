"""The car monitor's runs as the ``fdikit car`` commands make them: the HTML report of a simulated
scenario (:func:`scenario_report`), and the RAV4 lateral monitor on the recorded minute with faults
injected (:func:`rav4_log_run`), drawn (:func:`rav4_log_figure`) and reported
(:func:`rav4_log_report`)."""

from __future__ import annotations

from pathlib import Path

__all__ = ["RAV4_UNITS", "describe_injected", "rav4_log_figure", "rav4_log_report", "rav4_log_run",
           "scenario_report"]


def scenario_report(out: dict, path: str | Path):
    """Write the HTML report of a scenario run: signals, residual norms, probabilities, events.

    Parameters
    ----------
    out : dict
        What :func:`fdikit.systems.car.scenarios.run_scenario` returns.
    path : str or Path
        The ``.html`` file to write.

    Returns
    -------
    Path
        The written report.
    """
    from ...report import monitor_report

    s = out["summary"]
    sig = out["inputs"].concat_channels(out["measurements"])
    stats = out["features"].concat_channels(out["probabilities"])
    meta = {
        "scenario": s["name"],
        "description": s["description"],
        "block": s["block"],
        "injected": "{target} {magnitude} from {onset_s} s".format(**s["injected"]),
        "detection delay (s)": s["detection_delay_s"],
        "isolated": s["isolated"],
        "false announcements": len(s["false_announcements"]),
        "design": "calibrated in this run (fdikit.systems.car.monitor.calibrate_monitor)",
    }
    return monitor_report(
        path,
        signals=sig,
        statistics=stats,
        events=out.get("events", []),
        level=s.get("announcement_level"),
        title=f"fdikit car scenario: {s['name']}",
        meta=meta,
    )


#: Units of the RAV4 monitor channels (fdikit.systems.car.monitor_rav4.CHANNELS and the speed).
RAV4_UNITS = {
    "steer": "rad",
    "speed": "m/s",
    "a_y": "m/s^2",
    "yaw_rate": "rad/s",
    "w_front_diff": "m/s",
    "w_rear_diff": "m/s",
}


def rav4_log_run(path: str | Path, inject: str = "none"):
    """The RAV4 lateral monitor on the recorded minute in ``path`` with faults injected, for a
    figure and a report (the design is cached).

    Parameters
    ----------
    path : str or Path
        Data folder with ``drive.blf`` and ``toyota_rav4.dbc``.
    inject : str
        Faults to inject (:func:`fdikit.systems.car.monitor_rav4.parse_inject`), ``"none"`` for none.

    Returns
    -------
    tuple
        ``(monitor, faults, signals, result)``: the fitted and calibrated RAV4 monitor, the parsed
        faults, the raw signals with the faults injected and the monitor's result on them.
    """
    from .monitor_rav4 import inject as inject_faults
    from .monitor_rav4 import parse_inject, rav4_monitor

    mon = rav4_monitor(str(path))
    faults = parse_inject(inject)
    sig = inject_faults(mon.raw, faults, mon.artifacts["filter"].pre)
    return mon, faults, sig, mon.run(sig)


def rav4_log_figure(mon, faults, sig, res, path: str | Path) -> str:
    """Draw a :func:`rav4_log_run`: the monitor channels (left), the residual norms and the fault
    probabilities (right), the announcements marked, the calibration half and the first injected
    fault shaded; saved to ``path`` (the format follows its extension). Returns the saved path."""
    from ...report.figures import panel_figure, save

    t = sig.t - sig.t[0]
    chans = mon.artifacts["filter"].monitor_channels(sig)
    col1 = [
        {
            "title": f"monitor channel {n}",
            "ylabel": n,
            "unit": u or RAV4_UNITS.get(n, ""),
            "traces": [(n, chans.values[0, :, j])],
            "legend": False,
        }
        for j, (n, u) in enumerate(zip(chans.names, chans.units))
    ]
    st = res.statistics
    feats = [n for n in st.names if n.startswith("|")]
    col2 = [
        {"title": n, "ylabel": "residual norm", "unit": "–", "traces": [(n, st[n][0])], "legend": False}
        for n in feats
    ]
    probs = [f"P:{f}" for f in mon.faults if f"P:{f}" in st.names]
    col2.append(
        {
            "title": "fault probabilities (MHSSPT)",
            "ylabel": "probability",
            "unit": "–",
            "ylim": (-0.05, 1.05),
            "thresholds": [("announce (held 10 samples)", 0.95)],
            "traces": [(n, st[n][0]) for n in probs],
        }
    )
    events = [(e.t - sig.t[0], e.hypothesis) for e in res.events]
    shade = [(f.start, float(f.end if f.end is not None else t[-1]), "fault", "tab:red") for f in faults[:1]]
    half = mon.record.get("half_s")
    if half:
        shade.append((0.0, float(half), "calibration", "0.6"))
    fig = panel_figure(
        t,
        [col1, col2],
        title=f"RAV4 lateral monitor, injected: {describe_injected(faults, mon.artifacts['filter'].pre)} "
        "(grey: calibration half; red: injected fault)",
        events=events,
        shade=shade,
        panel_size=(6.0, 1.35),
    )
    return save(fig, path)


def describe_injected(faults, pre=None) -> str:
    """A one-line description of injected faults (Fault objects or (channel, magnitude, start) biases).

    With the RAV4 preprocessing ``pre`` a fault on a CAN name says what each signal receives, in
    its DBC unit (:func:`fdikit.systems.car.monitor_rav4.injection.injection_summary`).

    Examples
    --------
    >>> describe_injected([("yaw_rate", 0.03, 40.0)])
    'yaw_rate +0.03 from 40 s'
    >>> describe_injected([])
    'none'
    >>> from fdikit.systems.car.monitor_rav4 import Rav4Preprocessing, parse_inject
    >>> describe_injected(parse_inject("bias:STEER_ANGLE:3@20"), Rav4Preprocessing(16, 0, 0, 0, 1, 0, 0))
    'bias on STEER_ANGLE_SENSOR.STEER_ANGLE (magnitude 3 deg) from 20 s'
    """
    if pre is not None and faults and not isinstance(faults[0], tuple):
        from .monitor_rav4.injection import injection_summary

        out = []
        for f in injection_summary(faults, pre):
            parts = []
            for a in f["applied"]:
                unit = {"gain": "", "slope": f" {a['unit']}/s"}
                v = ", ".join(f"{k} {x:g}{unit.get(k, ' ' + a['unit'])}" if isinstance(x, float)
                              else f"{k} {x}"
                              for k, x in a.items() if k not in ("signal", "unit") and x is not None)
                parts.append(a["signal"] + (f" ({v})" if v else ""))
            what = " and ".join(parts) or f["target"]
            out.append(f"{f['fault']} on {what} from {f['start_s']:g} s")
        return ", ".join(out)
    out = []
    for f in faults:
        if isinstance(f, tuple):
            out.append(f"{f[0]} {f[1]:+g} from {f[2]:g} s")
        else:
            val = {k: getattr(f, k) for k in ("magnitude", "slope", "gain", "value") if hasattr(f, k)}
            v = ", ".join(f"{k} {x:g}" for k, x in val.items() if x is not None)
            what = f"{type(f).__name__.lower()} on {f.target}" + (f" ({v})" if v else "")
            out.append(f"{what} from {f.start:g} s")
    return ", ".join(out) or "none"


def rav4_log_report(mon, faults, sig, res, path: str | Path, data: str | Path) -> str:
    """Write the HTML report of a :func:`rav4_log_run` (raw and monitor signals, residual norms,
    probabilities, events; times from the start of the log) to ``path``; ``data`` is the data folder
    it names. Returns the written path."""
    from ...monitor import MonitorResult
    from ...report import monitor_report, monitor_thresholds
    from ...signals import Signals

    t0 = sig.t[0]
    meta = {
        "data": str(data),
        "injected": describe_injected(faults, mon.artifacts["filter"].pre),
        "calibrated on (s)": mon.record.get("half_s"),
        "design": "fitted and calibrated in this run (fdikit.systems.car.monitor_rav4.rav4_monitor)",
    }
    sig0 = Signals(sig.t - t0, sig.values, sig.names, sig.units, check=False)
    shift = lambda s: Signals(s.t - t0, s.values, s.names, s.units, check=False)  # noqa: E731
    r0 = MonitorResult(
        shift(res.residuals),
        shift(res.statistics),
        [type(e)(e.run, e.k, e.t - t0, e.hypothesis, e.value) for e in res.events],
        res.valid,
        res.invalid,
    )
    return str(
        monitor_report(
            path,
            signals=sig0,
            result=r0,
            thresholds=monitor_thresholds(mon.monitor),
            level=float(mon.decision.level),
            title="fdikit car monitor-log: RAV4 lateral monitor",
            meta=meta,
        )
    )
