"""The HTML report: display decimation keeps every spike, a run's report holds its events, a
campaign's report holds its tables, and bad input is named (fast; the browser test is in
test_report_browser.py)."""

from __future__ import annotations

import base64
import json
import time

import numpy as np
import pytest

from fdikit import Signals
from fdikit.errors import DataError
from fdikit.report import (
    campaign_report,
    check_output_path,
    minmax_decimate,
    monitor_report,
    read_events_jsonl,
    report_from_files,
    roc_curve,
    true_intervals,
)


def _page(path):
    html = path.read_text()
    data = json.loads(
        html.split("id='fdikit-report-data'>", 1)[1].split("</script>", 1)[0].replace("<\\/", "</")
    )
    figs = json.loads(html.split("id='fdikit-figures'>", 1)[1].split("</script>", 1)[0].replace("<\\/", "</"))
    return html, data, figs


def _decode(arr):
    return np.frombuffer(base64.b64decode(arr["bdata"]), {"f8": "<f8", "f4": "<f4"}[arr["dtype"]])


# ---------------------------------------------------------------------------------- decimation
def test_a_spike_in_a_long_log_survives_decimation():
    rng = np.random.default_rng(0)
    n = 3_600_001  # one hour at 1 kHz
    t = np.arange(n) * 1e-3
    y = rng.normal(0.0, 0.01, n)
    k = 1_234_567
    y[k] = 5.0  # one sample
    y[2_000_000] = -4.0
    td, yd = minmax_decimate(t, y, 3000)
    assert td.size <= 3000 and np.all(np.diff(td) > 0)
    assert yd.max() == 5.0 and td[yd.argmax()] == t[k]
    assert yd.min() == -4.0 and td[yd.argmin()] == t[2_000_000]
    # the envelope is kept: every bucket's extremes are the true extremes of that stretch
    assert np.isclose(yd[(td > 100) & (td < 1000)].max(), y[(t > 100) & (t < 1000)].max(), atol=0.02)
    # a plain stride decimation to the same size loses the spike: the test can fail
    stride = n // 3000 + 1
    assert y[::stride].max() < 1.0


def test_decimation_keeps_gaps_and_short_records():
    t = np.arange(100_000) * 0.01
    y = np.sin(t)
    y[50_000:50_010] = np.nan
    td, yd = minmax_decimate(t, y, 900)
    assert np.isnan(yd).any() and 500.0 <= td[np.isnan(yd)][0] < 500.1
    t2, y2 = minmax_decimate(t[:50], y[:50], 900)
    assert t2.size == 50 and np.array_equal(y2, y[:50])
    with pytest.raises(DataError):
        minmax_decimate(t, y[:-1], 900)


def test_true_intervals_cover_every_flagged_sample():
    t = np.arange(10_000) * 0.1
    m = np.zeros(t.size, bool)
    m[5::7] = True  # 1428 separate samples: merged into at most ~max_intervals stretches
    iv = true_intervals(t, m, max_intervals=50)
    assert len(iv) <= 60
    covered = np.zeros(t.size, bool)
    for a, b in iv:
        covered |= (t >= a) & (t <= b)
    assert covered[m].all()


def test_roc_against_a_closed_form():
    # nominal N(0,1), faulty N(2,1): the AUC is Phi(2 / sqrt 2) = 0.9214
    rng = np.random.default_rng(1)
    r = roc_curve(rng.normal(0, 1, 20000), rng.normal(2, 1, 20000), n=400)
    assert abs(r["auc"] - 0.9214) < 0.01
    assert r["pf"][0] == 0 and r["pd"][-1] == 1 and np.all(np.diff(r["pf"]) >= 0)


# --------------------------------------------------------------------------- golden structure
@pytest.fixture(scope="module")
def two_mass_run():
    from fdikit.faults import Bias
    from fdikit.monitor import Decision, Monitor
    from fdikit.residuals import ObserverResidual
    from fdikit.systems import two_mass

    designs = two_mass.design({"seed": 0, "runs": 60})
    gen = ObserverResidual(designs["observer"])
    hold = designs["hold"]
    names = {"r:pos1:alarm": "sensor:pos1", "r:pos2:alarm": "sensor:pos2"}
    mon = Monitor([gen], [hold], Decision(hold.output_names, names=names), on_invalid="hold")
    sig = two_mass.record([Bias("sensor:pos2", 0.03, start=6.0)], 1, 2, duration=10.0)
    v = sig.values.copy()
    v[0, 200:215, 1] = np.nan
    sig = Signals(sig.t, v, sig.names, ["N", "m", "m"], check=False)
    return sig, mon, mon.run(sig)


def test_report_of_a_known_event_holds_the_event_its_time_and_its_fault(tmp_path, two_mass_run):
    sig, mon, res = two_mass_run
    after = [e for e in res.events if e.t >= 6.0 and e.hypothesis == "sensor:pos2"]
    assert after, res.events  # the run has the known event
    ev = after[0]
    path = monitor_report(tmp_path / "r.html", signals=sig, result=res, monitor=mon)
    html, data, figs = _page(path)
    got = [e for e in data["events"] if e["hypothesis"] == "sensor:pos2" and e["t"] >= 6.0]
    assert got and got[0]["t"] == pytest.approx(ev.t) and got[0]["sample"] == ev.k
    assert f"<td>{round(ev.t, 4):.5g}</td>" in html and "<td>sensor:pos2</td>" in html  # the event table
    # the timeline marks it, the signal panels draw a line at it, the held gap is shaded
    timeline = next(f for f in figs if f["layout"]["title"]["text"] == "events timeline")
    tr = next(t for t in timeline["data"] if t.get("name") == "sensor:pos2")
    assert ev.t in tr["x"]
    signals = next(f for f in figs if f["layout"].get("title", {}).get("text") == "monitor input signals")
    assert any(s["type"] == "line" and s["x0"] == ev.t for s in signals["layout"]["shapes"])
    held = [s for s in signals["layout"]["shapes"] if s["type"] == "rect" and s["yref"] == "paper"]
    assert held and held[0]["x0"] < sig.t[200] and held[0]["x1"] > sig.t[214]
    # thresholds drawn on the residuals, units on the axes
    resid = next(f for f in figs if f["layout"].get("title", {}).get("text") == "residuals")
    thr = float(mon.processors[0].threshold[1])
    assert any(s["type"] == "line" and s.get("y0") == pytest.approx(thr) for s in resid["layout"]["shapes"])
    assert signals["layout"]["yaxis2"]["title"]["text"] == "pos1 (m)"
    assert data["counts"]["held_samples"] == 15
    # plotly.js embedded once, nothing fetched from elsewhere
    assert html.count("Plotly.newPlot(") == 1 and "<script src" not in html and "<link" not in html


def test_report_from_monitor_files_names_bad_input(tmp_path, two_mass_run):
    _sig, _mon, _res = two_mass_run
    bad = tmp_path / "ev.jsonl"
    bad.write_text('{"t": 1.0, "hypothesis": "x", "run": 0}\nnot json\n')
    with pytest.raises(DataError, match=r"ev.jsonl, line 2"):
        read_events_jsonl(bad)
    with pytest.raises(DataError, match="no such statistics file"):
        report_from_files(tmp_path / "r.html", stats=tmp_path / "missing.parquet")
    with pytest.raises(DataError, match="nothing to report"):
        report_from_files(tmp_path / "r.html")
    with pytest.raises(DataError, match="does not exist"):
        check_output_path(tmp_path / "no" / "such" / "r.html")
    with pytest.raises(DataError, match="must end in"):
        check_output_path(tmp_path / "r.png")


def test_report_command_checks_the_output_before_any_work(tmp_path, capsys):
    from fdikit.cli import main

    t0 = time.perf_counter()
    rc = main(["report", str(tmp_path / "missing" / "r.html"), "--campaign", str(tmp_path / "c.json")])
    assert rc == 2 and "does not exist" in capsys.readouterr().err
    assert time.perf_counter() - t0 < 2.0


CAMPAIGN = {
    "snr_db": 23.0,
    "runs": {"F0": 40, "F1": 20, "F2": 20},
    "pf": {"T1": 0.0, "T2": 0.025},
    "pd": {"F1": {"T1": 0.95, "T2": 0.1}, "F2": {"T1": 0.05, "T2": 1.0}},
    "dmatrix": {
        "faults": ["F0", "F1", "F2"],
        "tests": ["T1", "T2"],
        "d": [[0, 0], [1, 0], [0, 1]],
        "pd": [[0.0, 0.025], [0.95, 0.1], [0.05, 1.0]],
    },
    "confusion": {"F0": {"F0": 39, "F2": 1}, "F1": {"F1": 19, "F0": 1}, "F2": {"F2": 20}},
    "sensitivity": 0.975,
    "specificity": 0.975,
    "detection_time_histogram": {"edges": [0.0, 0.5, 1.0], "counts": {"F1": [12, 7]}},
}


def test_campaign_report_holds_every_table_and_plot(tmp_path):
    path = campaign_report(CAMPAIGN, tmp_path / "c.html")
    html, _data, figs = _page(path)
    titles = [f["layout"]["title"]["text"] for f in figs]
    assert titles == [
        "Pd / Pf per test and class",
        "D-matrix",
        "confusion matrix",
        "detection-time histogram",
    ]
    pdpf = figs[0]["data"][0]
    assert pdpf["y"] == ["F0 (Pf)", "F1", "F2"] and pdpf["z"][1] == [0.95, 0.1]
    conf = figs[2]["data"][0]
    assert conf["z"][0][conf["x"].index("F2")] == pytest.approx(1 / 40)
    assert "<td>sensitivity</td><td>97.5</td>" in html
    with pytest.raises(DataError, match="not a campaign result"):
        campaign_report({"hello": 1}, tmp_path / "x.html")
    cj = tmp_path / "c.json"
    cj.write_text(json.dumps({**CAMPAIGN, "roc": {"T1": roc_curve([0, 1, 2], [1, 2, 3])}}))
    out = report_from_files(tmp_path / "c2.html", campaign=cj)
    assert out["kind"] == "campaign" and out["figures"] == 5


def test_abs_campaign_json_makes_a_report(tmp_path):
    """The real campaign JSON (a tiny campaign) goes through ``fdikit report --campaign``."""
    from fdikit.cli import main
    from fdikit.systems.abs.campaign import run_campaign

    camp = run_campaign(runs=3, nominal_runs=4, design_runs=8, pfa=0.2).to_dict()
    cj = tmp_path / "campaign.json"
    cj.write_text(json.dumps(camp, default=float))
    out = tmp_path / "c.html"
    assert main(["report", str(out), "--campaign", str(cj), "--json"]) == 0
    _html, data, figs = _page(out)
    titles = [f["layout"]["title"]["text"] for f in figs]
    assert {"Pd / Pf per test and class", "D-matrix", "confusion matrix", "detection-time histogram"} <= set(
        titles
    )
    assert data["campaign"]["pf"] == camp["pf"]


def test_events_timeline_draws_episodes_from_onset_to_cleared(tmp_path):
    """Issue 16 item 4 in the report: an onset and its cleared event make one episode bar and one
    row of the episode table; a second onset with no cleared event is open to the record's end."""
    from fdikit.monitor import Event
    from fdikit.report import Report, add_events

    rep = Report("episodes")
    ev = [Event(0, 100, 1.0, "sensor:a", 0.9, kind="onset", size=0.25, episode=0),
          Event(0, 300, 3.0, "sensor:a", 0.1, kind="cleared", episode=0),
          Event(0, 500, 5.0, "sensor:b", 0.8, kind="onset", episode=0)]
    add_events(rep, ev, (0.0, 9.0))
    html = rep.to_html()
    assert "2 announcement(s) (fault episodes), 1 cleared" in html
    assert "<td>open</td>" in html and "<td>0.25</td>" in html
    bars = [d for f in rep._figures for d in f["data"] if d.get("name", "").endswith("episodes")]
    assert [(b["name"], b["x"]) for b in bars] == [("sensor:a episodes", [1.0, 3.0, None]),
                                                   ("sensor:b episodes", [5.0, 9.0, None])]
