"""The aircraft reconstruction drawn: ng-tan-edwards-kuang Fig. 1 as an image
(:func:`reconstruction_figure`) and the run's HTML report (:func:`reconstruction_report`), from a
:func:`~fdikit.systems.aircraft.reconstruction.run_aircraft` run that kept its signals."""

from __future__ import annotations

from pathlib import Path

__all__ = ["reconstruction_figure", "reconstruction_report"]


def reconstruction_figure(res: dict, path: str | Path) -> str:
    """Ng, Tan, Edwards & Kuang, Fig. 1: the fault (left) and its reconstruction (right), with
    units, the fault's onset marked and the reconstruction error below.

    Parameters
    ----------
    res : dict
        What :func:`~fdikit.systems.aircraft.reconstruction.run_aircraft` returns with
        ``keep_signals=True`` (``t``, ``f``, ``fhat``, ``fhat_nominal`` in s and rad).
    path : str or Path
        The image file to write; the format follows its extension.

    Returns
    -------
    str
        The saved path.
    """
    import numpy as np

    from ...report.figures import panel_figure, save

    t, f, fh, fn = res["t"], res["f"], res["fhat"], res["fhat_nominal"]
    onset = float(t[np.flatnonzero(f != 0)[0]]) if np.any(f != 0) else None
    pad = 0.5 * max(float(np.ptp(f)), 1e-3)
    lim = (float(f.min()) - pad, float(f.max()) + pad)  # clips the observers' initial transient
    left = [
        {
            "title": "fault f (rudder actuator)",
            "ylabel": "f",
            "unit": "rad",
            "ylim": lim,
            "traces": [("f", f, {"color": "k"})],
            "legend": False,
        }
    ]
    right = [
        {
            "title": f"reconstruction f^ (RMS error ratio {res['rmse_ratio']:.3f} with uncertainty)",
            "ylabel": "f^",
            "unit": "rad",
            "ylim": lim,
            "traces": [
                ("with uncertainty", fh, {"color": "tab:blue"}),
                ("nominal plant", fn, {"color": "tab:red", "ls": "--", "lw": 0.8}),
            ],
        },
        {
            "title": f"reconstruction error (scored from t = {res['settle_s']:g} s)",
            "ylabel": "f^ - f",
            "unit": "rad",
            "ylim": (-0.25 * pad, 0.25 * pad),
            "traces": [
                ("with uncertainty", fh - f, {"color": "tab:blue"}),
                ("nominal plant", fn - f, {"color": "tab:red", "lw": 0.8}),
            ],
        },
    ]
    events = [(onset, "fault starts")] if onset is not None else []
    fig = panel_figure(
        t,
        [left, right],
        title="actuator fault reconstruction, cascaded sliding mode observers (ng-tan-edwards-kuang, Fig. 1)",
        events=events,
        panel_size=(5.2, 2.3),
    )
    return save(fig, path, dpi=120)


def reconstruction_report(res: dict, path: str | Path) -> str:
    """Write the HTML report of an aircraft reconstruction run: the design record, the fault, its
    reconstruction and the reconstruction error (interactive plots).

    Parameters
    ----------
    res : dict
        What :func:`~fdikit.systems.aircraft.reconstruction.run_aircraft` returns with
        ``keep_signals=True``.
    path : str or Path
        The ``.html`` file to write.

    Returns
    -------
    str
        The written path.
    """
    import numpy as np

    from ...report import Report, add_events, stacked_time_figure

    rep = Report("fdikit reconstruct aircraft: actuator fault reconstruction (ng-tan-edwards-kuang)")
    rep.section(
        "Run",
        "Cascaded sliding mode observers designed by LMIs; the aircraft simulated with and without "
        "the model uncertainty.",
    )
    from ... import __version__

    c = res["conditions"]
    info = {
        "fdikit version": __version__,
        "case": res["case"],
        "conditions A1, A2, B1, B2": c,
        "rank CM": res["rank_CM"],
        "pbar": res["pbar"],
        "L2 bound gamma-bar": res["l2_bound"],
        "paper's L2 bound": res["l2_bound_paper"],
        "H-inf of G(s)": (res["hinf_check"] or {}).get("hinf_bisection"),
        "RMS(f^ - f) / RMS(f), with uncertainty": res["rmse_ratio"],
        "RMS(f^ - f) / RMS(f), nominal": res["rmse_ratio_nominal"],
        "scored from (s)": res["settle_s"],
        "step h (s)": res["h"],
        "simulated (s)": res["t_final"],
        "uncertainty reading": res["uncertainty_reading"],
        "design (s)": res["design_seconds"],
        "simulation, two runs (s)": res["sim_seconds_two_runs"],
    }
    rep.table(info)
    rep.data["metadata"] = {k: v for k, v in info.items() if isinstance(v, int | float | str)}
    t, f = res["t"], res["f"]
    onset = float(t[np.flatnonzero(f != 0)[0]]) if np.any(f != 0) else None
    add_events(rep, [], (float(t[0]), float(t[-1])), title="Events")
    rep.text(
        "No announcements: a reconstructor estimates the fault signal; the dotted line marks the "
        "fault's onset."
    )
    pad = 0.5 * max(float(np.ptp(f)), 1e-3)
    marks = [(onset, "fault starts")] if onset is not None else []
    rep.section(
        "Fault and reconstruction",
        "The rudder actuator fault f and its reconstruction f^ (with the "
        "uncertain plant and the nominal one), and the reconstruction errors (decimated for display, "
        "keeping each bucket's minimum and maximum).",
    )
    panels = [
        {
            "title": "fault and reconstruction",
            "ylabel": "rudder fault",
            "unit": "rad",
            "range": [float(f.min()) - pad, float(f.max()) + pad],
            "traces": [
                ("f", f),
                ("f^ (with uncertainty)", res["fhat"]),
                ("f^ (nominal)", res["fhat_nominal"]),
            ],
        },
        {
            "title": "reconstruction error",
            "ylabel": "f^ - f",
            "unit": "rad",
            "range": [-0.25 * pad, 0.25 * pad],
            "traces": [("with uncertainty", res["fhat"] - f), ("nominal", res["fhat_nominal"] - f)],
        },
    ]
    rep.figure(
        stacked_time_figure(
            t, panels, title="fault reconstruction", events=marks, max_points=rep.max_points, panel_height=260
        )
    )
    return str(rep.write(path))
