"""Every ``--plot`` figure has labelled axes with units, and marks its events (the matplotlib
objects are checked, not pixels): each command runs with --plot and the figure it saves is
captured at ``savefig``."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fdikit.report.figures import axes_without_units

ROOT = Path(__file__).resolve().parents[2]
RAV4 = ROOT.parent / "shared" / "data" / "rav4-highway"


@pytest.fixture
def saved(monkeypatch):
    """The figures saved while the test runs (Figure.savefig still writes the file)."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    figs = []
    orig = Figure.savefig

    def spy(self, *a, **kw):
        figs.append(self)
        return orig(self, *a, **kw)

    monkeypatch.setattr(Figure, "savefig", spy)
    return figs


def _event_lines(fig) -> list[float]:
    xs = []
    for ax in fig.axes:
        for ln in ax.lines:
            x = np.asarray(ln.get_xdata(), float)
            if x.size == 2 and x[0] == x[1] and ln.get_linestyle() == ":":
                xs.append(float(x[0]))
    return xs


def _check(figs, path: Path, n_axes: int):
    assert path.exists() and path.stat().st_size > 10_000
    assert len(figs) == 1
    fig = figs[0]
    assert len([a for a in fig.axes if a.get_visible()]) >= n_axes
    assert axes_without_units(fig) == []
    return fig


def test_the_unit_check_can_fail():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(2, 1, sharex=True)
    ax[0].plot([0, 1], [0, 1])
    ax[0].set_ylabel("speed")  # no unit
    ax[1].plot([0, 1], [0, 1])
    ax[1].set_ylabel("slip (–)")
    ax[1].set_xlabel("time (s)")
    bad = axes_without_units(fig)
    assert len(bad) == 1 and "speed" in bad[0]
    ax[0].set_ylabel("speed (m/s)")
    assert axes_without_units(fig) == []
    plt.close(fig)


def test_abs_simulate_plot(tmp_path, saved):
    from fdikit.cli import main

    out = tmp_path / "fig3.png"
    assert (
        main(["abs", "simulate", "--fault", "F3", "--magnitude", "-0.05", "--json", "--plot", str(out)]) == 0
    )
    fig = _check(saved, out, 4)
    assert len(_event_lines(fig)) >= 4 * 3  # brake applied, ABS engaged, ABS off (and stopped) in each panel


@pytest.mark.parametrize("number", [3, 7, 9])
def test_abs_figure_fast(tmp_path, saved, number):
    from fdikit.cli import main

    out = tmp_path / f"fig{number}.png"
    assert main(["abs", "figure", str(number), "--plot", str(out), "--design-runs", "40", "--json"]) == 0
    fig = _check(saved, out, 2)
    if number in (7, 9):
        # the designed threshold is drawn in every panel
        for ax in fig.axes:
            assert any(np.ptp(ln.get_ydata()) == 0 and ln.get_linestyle() == "--" for ln in ax.lines)


@pytest.mark.slow
@pytest.mark.parametrize("number", [8, 10, 15, 16])
def test_abs_figure_slow(tmp_path, saved, number):
    from fdikit.cli import main

    out = tmp_path / f"fig{number}.png"
    assert (
        main(
            [
                "abs",
                "figure",
                str(number),
                "--plot",
                str(out),
                "--runs",
                "30",
                "--design-runs",
                "60",
                "--per-size",
                "2",
                "--json",
            ]
        )
        == 0
    )
    _check(saved, out, 2)


def test_reconstruct_plot(tmp_path, saved):
    from fdikit.cli import main

    out = tmp_path / "fig1.png"
    assert (
        main(["reconstruct", "aircraft", "--t-final", "3", "--h", "1e-4", "--plot", str(out), "--json"]) == 0
    )
    fig = _check(saved, out, 3)
    assert any(abs(x - 2.0) < 1e-3 for x in _event_lines(fig))  # the fault's onset


def _fake_scenario():
    """A scenario result with the structure of run_scenario's (for the figure alone)."""
    from fdikit import Signals
    from fdikit.monitor import Event
    from fdikit.systems.car.scenarios import SCENARIOS

    sc = SCENARIOS["brake_actuator_short"]
    t = np.arange(900) * 0.01
    rng = np.random.default_rng(0)
    on = t >= sc.onset
    feats = np.abs(rng.normal(0, 0.1, (1, t.size, 3)))
    feats[0, :, 2] *= 100.0  # one residual 100 times the others: it must not swamp them
    feats[0, on, 0] += 1.0
    P = np.zeros((1, t.size, 2))
    P[0, on, 0] = 1.0
    U = np.zeros((1, t.size, 3))
    U[0, :, 0] = 10.0
    Y = np.zeros((1, t.size, 3))
    Y[0, on, 2] = sc.magnitude
    summary = {
        "name": "brake_actuator_short",
        "description": sc.description,
        "block": sc.block,
        "fault": sc.fault,
        "injected": {"target": sc.target, "magnitude": sc.magnitude, "onset_s": sc.onset},
        "announcement_level": 0.5,
    }
    return {
        "summary": summary,
        "t": t,
        "features": Signals(t, feats, ["|a|", "|b|", "|c|"], check=False),
        "probabilities": Signals(t, P, [f"P:{sc.fault}", "P:throttle"], check=False),
        "inputs": Signals(t, U, ["throttle", "brake", "steer"], ["deg", "MPa", "rad"], check=False),
        "measurements": Signals(
            t, Y, ["w_engine", "a_x", "brake_meas"], ["rad/s", "m/s^2", "MPa"], check=False
        ),
        "events": [Event(0, 701, 7.01, sc.fault, 1.0)],
    }


def test_car_scenario_figure_units_events_and_no_swamping(tmp_path, saved):
    from fdikit.systems.car.scenarios import plot_scenario

    out = tmp_path / "fig5.png"
    plot_scenario(_fake_scenario(), str(out))
    fig = _check(saved, out, 3 + 2 + 4)
    assert 7.01 in _event_lines(fig)  # the announcement is marked
    # each residual has its own panel, normalised by its fault-free spread: none swamps another
    res_axes = [a for a in fig.axes if a.get_ylabel().startswith("norm / fault-free")]
    assert len(res_axes) == 3
    for ax in res_axes:
        assert len(ax.lines[0].get_ydata()) > 0 and ax.get_ylim()[1] < 30
    # the brake panel shows the command (0) and the measured pressure (what the driver did)
    brake = next(a for a in fig.axes if a.get_ylabel() == "brake pressure (MPa)")
    labels = [ln.get_label() for ln in brake.lines]
    assert "brake command (monitor input)" in labels and "brake pressure measured" in labels
    meas = next(ln for ln in brake.lines if ln.get_label() == "brake pressure measured")
    assert np.max(meas.get_ydata()) == pytest.approx(0.5)


@pytest.mark.slow
@pytest.mark.parametrize(
    "name", ["accel_bias_0.6", "brake_actuator", "steering_actuator", "intermittent_front_wheel"]
)
def test_car_scenario_plot_papers_figures(tmp_path, saved, name):
    """ng-chen-speyer Figs. 4-7 from ``fdikit car scenario NAME --plot``."""
    from fdikit.cli import main

    out = tmp_path / f"{name}.png"
    assert main(["car", "scenario", name, "--plot", str(out), "--json"]) == 0
    fig = _check(saved, out, 9)
    assert _event_lines(fig)


@pytest.mark.slow
@pytest.mark.skipif(not (RAV4 / "drive.blf").exists(), reason=f"the RAV4 minute is absent ({RAV4})")
def test_car_monitor_log_plot(tmp_path, saved):
    from fdikit.cli import main

    out = tmp_path / "rav4.png"
    assert (
        main(["car", "monitor-log", str(RAV4), "--inject", "yaw_rate:0.03@40", "--plot", str(out), "--json"])
        == 0
    )
    fig = _check(saved, out, 8)
    assert any(40.0 < x < 41.0 for x in _event_lines(fig))


def test_plot_to_a_missing_folder_fails_before_any_work(tmp_path, capsys):
    from fdikit.cli import main

    assert main(["reconstruct", "aircraft", "--plot", str(tmp_path / "nope" / "f.png")]) == 2
    assert "does not exist" in capsys.readouterr().err


def test_monitor_figure_for_the_monitor_command(tmp_path, saved):
    """The figure ``fdikit monitor --plot`` draws (fdikit.report.figures.monitor_figure)."""
    from fdikit import Signals
    from fdikit.faults import Bias
    from fdikit.monitor import Decision, Monitor
    from fdikit.report import monitor_thresholds
    from fdikit.report.figures import monitor_figure
    from fdikit.residuals import ObserverResidual
    from fdikit.systems import two_mass

    designs = two_mass.design({"seed": 0, "runs": 40})
    gen = ObserverResidual(designs["observer"])
    hold = designs["hold"]
    mon = Monitor([gen], [hold], Decision(hold.output_names), on_invalid="hold")
    sig = two_mass.record([Bias("sensor:pos2", 0.03, start=5.0)], 1, 2)
    sig = Signals(sig.t, sig.values, sig.names, ["N", "m", "m"], check=False)
    res = mon.run(sig)
    out = tmp_path / "mon.png"
    monitor_figure(sig, res, str(out), thresholds=monitor_thresholds(mon))
    fig = _check(saved, out, 5)
    ev = [e.t for e in res.events]
    assert ev and set(ev[:30]) <= set(_event_lines(fig))  # the first 30 are marked (all in the report)
