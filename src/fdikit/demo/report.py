"""The demo's HTML report: per section its summary table and at least one interactive plot with
units (``_SECTION_REPORTS``).

The aircraft fault f against its reconstructions f̂; the ABS stop (speeds, wheel slip against the
desired slip, brake torque, pressures); the diagnosed ABS records (first alarm time of every test, the
GLRT statistics against their thresholds); the directional test (fraction of stops each test fired in,
its I_w estimate over time); the car's drive with the driver's foot on the brake; the car monitor
(features, fault probabilities with the announcement level, the events timeline). The plotted series
come from the sections' ``demo_summary(details=)`` (the aircraft's is the run its ``demo_summary``
makes, with its time histories), so nothing is simulated twice; the page data's
``figures_per_section`` counts the plots of each section.
"""

from __future__ import annotations

from collections.abc import Callable

__all__ = ["default_report_path", "write_report"]


def _linear_report(rep, det: dict) -> None:
    """The linear section in full: the monitor run, the fault signature and an ROC."""
    import numpy as np

    from ..faults import Bias
    from ..report import add_monitor, add_roc, add_signature, monitor_thresholds, roc_curve
    from ..systems import two_mass

    mon, res = det["monitor"], det["result"]
    sig = det["signals"]
    from ..signals import Signals

    sig = Signals(sig.t, sig.values, sig.names, ["N", "m", "m"], check=False)
    add_monitor(rep, signals=sig, result=res, thresholds=monitor_thresholds(mon), title_prefix="linear: ")
    gen = mon.generators[0]
    thr = monitor_thresholds(mon)
    # the fault signature: mean |residual| / threshold after the onset, for each sensor fault
    faults = ["sensor:pos1", "sensor:pos2"]
    sigm = np.zeros((len(faults), len(gen.output_names)))
    for i, f in enumerate(faults):
        r = gen.run(two_mass.record([Bias(f, det["bias"], start=det["onset"])], 20, det["seed"] + 11))
        k = r.t >= det["onset"] + 1.0
        for j, n in enumerate(gen.output_names):
            sigm[i, j] = float(np.mean(np.abs(r[n][:, k]))) / thr[n][0]
    add_signature(rep, {"matrix": sigm, "rows": faults, "columns": gen.output_names,
                        "title": "linear: fault signature", "colorbar": "mean |r| / threshold (–)",
                        "intro": "Mean absolute residual from 1 s after the onset of a sensor bias of "
                        f"{det['bias']} m, in units of each residual's threshold (20 runs each): each fault "
                        "moves its own residual."})
    # ROC of the largest |r:pos2| per run, threshold swept (200 nominal, 200 faulty runs)
    nom = gen.run(two_mass.record([], 200, det["seed"] + 21))
    bad = gen.run(two_mass.record([Bias("sensor:pos2", det["bias"] / 3, start=det["onset"])], 200,
                                  det["seed"] + 22))
    k0 = nom.t >= 1.0
    rep.section("linear: ROC", f"Largest |r:pos2| of each run after 1 s, for a threshold swept over it: 200 "
                f"nominal runs against 200 runs with a pos2 bias of {det['bias'] / 3:.3g} m (a third of the "
                "demo's).")
    add_roc(rep, {"r:pos2, max over the run": roc_curve(np.abs(nom["r:pos2"][:, k0]).max(axis=1),
                                                        np.abs(bad["r:pos2"][:, k0]).max(axis=1))})


def _reconstruct_report(rep, det: dict, out: dict) -> None:
    """The aircraft rudder fault and its reconstruction by the cascaded sliding mode observers."""
    import numpy as np

    from ..report import stacked_time_figure

    r = det.get("run")
    if r is None or "fhat" not in r:  # the section made no run this demo could keep: make one
        from ..systems.aircraft.reconstruction import run_aircraft

        r = run_aircraft(t_final=float(out.get("t_final", 5.0)), h=1e-5, settle=1.0, noise_std=None,
                         keep_signals=True)
    t, f = r["t"], r["f"]
    settle = float(r.get("settle_s", 1.0))
    pad = 0.5 * max(float(np.ptp(f)), 1e-3)
    err, err0 = r["fhat"] - f, r["fhat_nominal"] - f
    e_max = max(float(np.max(np.abs(err[t >= settle]))), float(np.max(np.abs(err0[t >= settle]))), 1e-6)
    onset = float(t[np.flatnonzero(f != 0)[0]]) if np.any(f != 0) else None
    rep.section("reconstruct: fault and reconstruction",
                "The rudder actuator fault f and its reconstruction f̂ by the cascaded sliding mode "
                "observers (ng-tan-edwards-kuang Fig. 1), on the uncertain plant A + ΔA and on the nominal "
                "plant, and the reconstruction error. The observers start from zero: their initial "
                f"transient (|f̂| up to {float(np.max(np.abs(r['fhat'][t < settle]))):.3g} rad before "
                f"{settle:g} s) is "
                "off the initial scale; double-click a panel to autoscale. The RMS error ratios are scored "
                f"from {settle:g} s.")
    panels = [
        {"title": "rudder actuator fault", "ylabel": "fault", "unit": "rad",
         "range": (float(f.min()) - pad, float(f.max()) + pad),
         "traces": [("f (injected)", f), ("f̂ on A + ΔA", r["fhat"]),
                    ("f̂ on the nominal A", r["fhat_nominal"])]},
        {"title": f"reconstruction error (RMS ratio {r['rmse_ratio']:.3g} on A + ΔA, "
                  f"{r['rmse_ratio_nominal']:.3g} nominal)", "ylabel": "f̂ − f", "unit": "rad",
         "range": (-1.5 * e_max, 1.5 * e_max),
         "traces": [("f̂ − f on A + ΔA", err), ("f̂ − f on the nominal A", err0)]},
    ]
    events = [(settle, "scoring starts")] + ([(onset, "fault starts")] if onset is not None else [])
    rep.figure(stacked_time_figure(t, panels, title="aircraft rudder fault reconstruction", events=events,
                                   max_points=rep.max_points, panel_height=220))


def _abs_report(rep, det: dict, out: dict) -> None:
    """The ABS stop: speeds, wheel slip against the desired slip, brake torque, pressures."""
    from ..report import stacked_time_figure
    from ..systems.abs.figures import abs_stop_panels

    t, panels, events = abs_stop_panels(det["result"])
    rep.section("abs: the stop",
                f"One braking stop from {out.get('v0', 15.0):g} m/s with the sliding-mode PWM controller "
                "(luo-et-al Fig. 3): the controller holds the wheel slip near its desired value of 0.2 "
                "once the ABS engages, until the car is slow enough for the ABS to switch off.")
    rep.figure(stacked_time_figure(t, panels, title="ABS stop (nominal, 23 dB)", events=events,
                                   max_points=rep.max_points))


def _abs_diagnosis_report(rep, det: dict, out: dict) -> None:
    """Which tests fired, when, for each diagnosed record, and the GLRT statistics against their
    thresholds."""
    import numpy as np

    from ..report import heatmap_figure, stacked_time_figure
    from ..systems.abs.campaign import abs_residuals, residual_generators

    dg, records, cases = det["diagnoser"], det["records"], out["cases"]
    bank = dg.bank
    names = list(bank.names)

    def label(c):
        m = c["magnitude"]
        return f"{c['injected']}" + ("" if m is None else f" {100 * m:+g} %") + f" → {c['diagnosed']}"

    rows = [label(c) for c in cases]
    z = np.array([[c["fired"].get(n, np.nan) for n in names] for c in cases], float)
    text = [["" if not np.isfinite(v) else f"{v:.2f} s" for v in row] for row in z]
    rep.section("abs_diagnosis: tests fired",
                "First alarm time of every GLRT test in each diagnosed record (blank: the test did not "
                "fire); the rows name the injected fault and the diagnosis of the test-sequencing tree.")
    rep.figure(heatmap_figure(z, names, rows, title="first alarm time of each test",
                              colorbar="first alarm (s)", text=text, x_title="test",
                              y_title="injected fault → diagnosis (–)", colorscale="Viridis"))
    specs = [s for s in bank.specs if s.signature is None and s.gate is None]
    gens = residual_generators(bank.specs)
    stats = []
    for c, rec in zip(cases, records):
        res = abs_residuals(rec.y.concat_channels(rec.u), gens)
        stats.append((c, {s.name: bank.statistic(res, s).values[0, :, 0] for s in specs}, res.t))
    t = stats[0][2]
    panels = []
    for s in specs:
        thr = float(bank.thresholds[s.name])
        top = max([thr] + [float(np.nanmax(st[s.name])) for _, st, _ in stats])
        panels.append({"title": f"{s.name}: GLRT of {s.residual} (W = {s.W}, hold Z = {s.Z})",
                       "ylabel": f"GLRT {s.name}", "unit": "–", "log": True, "range": (thr / 1e3, 3 * top),
                       "thresholds": [(f"threshold {thr:.3g}", thr)],
                       "traces": [(label(c), np.where(st[s.name] > 0, st[s.name], np.nan))
                                  for c, st, _ in stats]})
    rep.section("abs_diagnosis: test statistics",
                "The GLRT statistics of the diagnosed records (logarithmic axes) with the designed "
                "thresholds (dashed); a test fires when its statistic stays above the threshold for Z "
                "samples.")
    rep.figure(stacked_time_figure(t, panels, title="GLRT statistics of the diagnosed records",
                                   events=[(0.5, "brake applied")], max_points=rep.max_points))


def _abs_directional_report(rep, det: dict, out: dict) -> None:
    """Fraction of runs each test fired in, and the directional test's I_w estimate over time."""
    import numpy as np

    from ..report import heatmap_figure, stacked_time_figure

    bank, cases = det["bank"], det["cases"]
    names = list(bank.names)
    labels = list(cases)
    z = np.array([cases[k]["fired"].mean(axis=0) for k in labels], float)
    runs = int(next(iter(cases.values()))["fired"].shape[0])
    rep.section("abs_directional: tests fired",
                f"Fraction of {runs} stops in which each test fired (thresholds for a 1 % false-alarm "
                "probability per test): the directional test G_D_Iw sees the I_w fault that no "
                "change-in-mean test sees; nothing sees tau_m +15 % (it fires as often as on the nominal "
                "stops).")
    rep.figure(heatmap_figure(z, names, labels, title="fraction of stops with an alarm",
                              colorbar="fraction (–)", zmin=0, zmax=1, x_title="test", y_title="stops (–)",
                              colorscale="Viridis"))
    spec = next((s for s in bank.specs if s.name == "G_D_Iw"), None)
    k_iw = next((k for k in labels if cases[k]["fault"] == "F4"), None)
    k_0 = next((k for k in labels if cases[k]["fault"] == "F0"), None)
    if spec is None or k_iw is None:
        return
    proc = bank.processor(spec)
    o_iw = proc.run(cases[k_iw]["residuals"])
    t = o_iw.t
    eta = o_iw[f"{spec.name}:eta"]
    truth = cases[k_iw]["magnitude"]
    g_traces = [(f"{k_iw}, stop 1", o_iw[f"{spec.name}:dglrt"][0])]
    if k_0 is not None:
        o_0 = proc.run(cases[k_0]["residuals"])
        g_traces.insert(0, (f"{k_0}, stop 1", o_0[f"{spec.name}:dglrt"][0]))
    thr = float(bank.thresholds[spec.name])
    panels = [
        {"title": f"directional GLRT {spec.name} along the I_w signature of r3 and r4",
         "ylabel": spec.name, "unit": "–", "thresholds": [(f"threshold {thr:.3g}", thr)], "traces": g_traces},
        {"title": f"its estimate of the relative I_w change ({k_iw}; median and 10-90 % of "
                  f"{eta.shape[0]} stops)",
         "ylabel": "ΔI_w / I_w", "unit": "–", "range": (-0.1, 0.06),
         "thresholds": [(f"true change {truth:+g}", float(truth))] if truth is not None else [],
         "traces": [("median", np.nanmedian(eta, axis=0)), ("10 %", np.nanpercentile(eta, 10, axis=0)),
                    ("90 %", np.nanpercentile(eta, 90, axis=0))]},
    ]
    rep.section("abs_directional: the I_w test",
                "The directional GLRT reads r3 and r4 along their I_w signature from the start of the stop "
                "and speaks once its estimate is resolved to 2 %; its amplitude estimate converges to the "
                "injected change.")
    rep.figure(stacked_time_figure(t, panels, title="I_w -2 %: directional test and estimate",
                                   events=[(0.5, "brake applied")], max_points=rep.max_points))


def _car_report(rep, det: dict, out: dict) -> None:
    """The short drive: the driver's foot on the brake and the speed controller's answer."""
    from ..report import stacked_time_figure

    res = det["drive"]
    onset = float(det.get("fault_onset_s", 0.4))
    t = res.u.t
    U, X = res.u, res.x

    def unit(sig, n):
        return sig.units[sig.names.index(n)]

    panels = [
        {"title": "longitudinal speed", "ylabel": "v_x", "unit": unit(X, "v_x"),
         "traces": [("v_x", X["v_x"][0])]},
        {"title": "throttle command (the speed controller)", "ylabel": "throttle",
         "unit": unit(U, "throttle"), "traces": [("throttle command", U["throttle"][0])]},
        {"title": "brake: command vs pressure (the fault is the driver's foot)", "ylabel": "brake pressure",
         "unit": unit(X, "p_b"),
         "traces": [("brake command", U["brake"][0]), ("brake pressure p_b", X["p_b"][0])]},
    ]
    rep.section("car: brake-actuator drive",
                "The automated passenger car (ng-chen-speyer) at 24 m/s: from "
                f"{onset:g} s the driver presses the brake (a brake-actuator fault, not commanded), and the "
                "speed controller answers with the throttle.")
    rep.figure(stacked_time_figure(t, panels, title="passenger car: driver's foot on the brake",
                                   events=[(onset, "brake fault")], max_points=rep.max_points))


def _car_monitor_report(rep, det: dict, out: dict) -> None:
    """The car health monitor's features, fault probabilities and announcements."""
    from ..report import add_monitor

    s = det["summary"]
    inj = s["injected"]
    rep.text(f"Injected: {inj['target']} {inj['magnitude']} from {inj['onset_s']} s; announced "
             f"{s['isolated']} {s['detection_delay_s']} s after the onset. Below: the monitor's events, its "
             "features (residual norms) and the posterior probability of every fault hypothesis.")
    stats = det["features"].concat_channels(det["probabilities"])
    add_monitor(rep, statistics=stats, events=det["events"], level=s.get("announcement_level"),
                title_prefix="car_monitor: ")


#: Section -> its part of the demo report (beyond the summary table): (function, details key check).
_SECTION_REPORTS: dict[str, tuple[Callable, str]] = {
    "reconstruct": (_reconstruct_report, ""),
    "abs": (_abs_report, "result"),
    "abs_diagnosis": (_abs_diagnosis_report, "records"),
    "abs_directional": (_abs_directional_report, "cases"),
    "car": (_car_report, "drive"),
    "car_monitor": (_car_monitor_report, "features"),
}


def write_report(path, summary: dict, details: dict) -> str:
    """Write the demo's HTML report of all sections run.

    Parameters
    ----------
    path : str or Path
        The ``.html`` file to write.
    summary : dict
        Section name -> its summary (:func:`~fdikit.demo.sections.run_sections`).
    details : dict
        Section name -> the series its part of the report plots.

    Returns
    -------
    str
        The written path.
    """
    from .. import __version__
    from ..report import Report

    rep = Report("fdikit demo")
    rep.section("Demo", "Every section of `fdikit demo`: what ran and what it found.")
    rep.table({"fdikit version": __version__, "sections": ", ".join(summary),
               "seconds": round(sum(v.get("seconds", 0.0) for v in summary.values()), 2)})
    figures: dict[str, int] = {}
    for name, out in summary.items():
        rep.section(f"{name}", (out.get("name") or out.get("plant") or out.get("scenario") or "") or None)
        rows = [{"key": k, "value": v if not isinstance(v, list) or len(v) <= 12 else f"{len(v)} items"}
                for k, v in out.items()]
        rep.table(rows, columns=["key", "value"])
        n0 = rep.n_figures
        det = details.get(name) or {}
        if name == "linear" and det:
            _linear_report(rep, det)
        elif name in _SECTION_REPORTS:
            func, needs = _SECTION_REPORTS[name]
            if not needs or needs in det:
                func(rep, det, out)
        figures[name] = rep.n_figures - n0
    rep.data["summary"] = summary
    rep.data["figures_per_section"] = figures
    return str(rep.write(path))


def default_report_path() -> str:
    """Where the demo writes its report by default: ``fdikit-demo-report.html`` in the system's
    temporary folder."""
    import tempfile
    from pathlib import Path

    return str(Path(tempfile.gettempdir()) / "fdikit-demo-report.html")
