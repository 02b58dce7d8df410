"""fdikit.evaluate.validate: a saved design's claims re-measured on nominal logs (issue 26)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from fdikit import Signals
from fdikit.errors import DataError
from fdikit.evaluate import claims_table, validate
from fdikit.faults import Bias
from fdikit.monitor.config import build_monitor, load_config, map_channels, run_design
from fdikit.systems import two_mass

ROOT = Path(__file__).resolve().parents[2]


def _log(faults=(), seed=0, runs=1):
    """A two-mass log in the config's source channels (F in N, P1 and P2 in mm)."""
    s = two_mass.record(faults, runs, seed)
    return Signals(s.t, s.values * np.array([1.0, 1000.0, 1000.0]), ["F", "P1", "P2"], check=False)


@pytest.fixture(scope="module")
def cfg(tmp_path_factory):
    d = tmp_path_factory.mktemp("val")
    shutil.copy(ROOT / "examples" / "two-mass" / "monitor.toml", d / "monitor.toml")
    c = load_config(d / "monitor.toml")
    run_design(c)
    return c


def test_measured_rates_equal_an_independent_count(cfg):
    """Runs of one Signals are records; the per-run rate counts the runs with an alarm, as a direct
    run of the monitor shows."""
    log = _log([Bias("sensor:pos2", 0.006, start=4.0)], seed=4, runs=6)   # a small bias: some runs alarm
    out = validate(cfg, log)
    res = build_monitor(cfg).run(map_channels(cfg, log))
    on = res.statistics.values[:, :, res.statistics.index(["r:pos2:alarm"])[0]] > 0.5
    judged = res.status == 0
    hit = np.any(on & judged, axis=1)
    assert 0 < hit.sum() < 6
    c = next(c for c in out["claims"] if c["name"] == "threshold r:pos2")
    assert c["measured"]["events"] == int(hit.sum()) and c["measured"]["rate"] == hit.mean()
    dec = next(c for c in out["claims"] if c["kind"] == "decision")
    assert dec["measured"]["events"] == len({e.run for e in res.events})
    assert out["samples"] == int(judged.sum())
    lines = claims_table(out)
    assert lines[1].startswith("claim") and any("threshold r:pos2" in ln for ln in lines)


def test_without_claims_the_announcements_are_still_measured(cfg, tmp_path):
    d = tmp_path / "c"
    shutil.copytree(cfg.path.parent, d)
    (d / "designs" / "design_report.json").unlink()
    out = validate(d / "monitor.toml", [_log(seed=9)])
    assert [c["name"] for c in out["claims"]] == ["decision (announcements)"]
    assert out["claims"][0]["verdict"] == "no claim" and out["contradicted"] == []
    assert out["rates"] == "not stated"


def test_bad_input_is_named(cfg):
    with pytest.raises(DataError, match="no nominal log"):
        validate(cfg, [])
    s = _log(seed=1)
    with pytest.raises(DataError, match=r"log 0: the log lacks the channel\(s\) pos2 \(source column 'P2'\)"):
        validate(cfg, Signals(s.t, s.values[:, :, :2], ["F", "P1"], check=False))


def test_announcement_claim_counts_the_design_runs_announcements(cfg):
    """A recipe's claim from its own nominal data: the events and judged time of the monitor's runs,
    with the exact Poisson interval; a fault-carrying run raises the count."""
    from scipy.stats import chi2

    from fdikit.evaluate import announcement_claim

    mon = build_monitor(cfg)
    res = [mon.run(map_channels(cfg, _log(seed=s, runs=3))) for s in (5, 6)]
    c = announcement_claim(res, "six simulated nominal runs")
    k = sum(len(r.events) for r in res)
    dt = float(np.diff(res[0].residuals.t[:2])[0])
    seconds = sum(float((r.status == 0).sum()) for r in res) * dt
    assert c["kind"] == "decision" and c["per"] == "hour" and c["target"] is None and c["events"] == k
    assert c["hours"] == pytest.approx(seconds / 3600.0)
    hi = chi2.ppf(0.975, 2 * k + 2) / 2 / (seconds / 3600.0)
    assert c["interval"][1] == pytest.approx(hi)
    faulty = mon.run(map_channels(cfg, _log([Bias("sensor:pos2", 0.02, start=2.0)], seed=7)))
    assert announcement_claim(faulty, "a fault")["events"] >= 1
    with pytest.raises(DataError, match="per must be a unit of time"):
        announcement_claim(res, "x", per="sample")
