"""Config-driven monitors: fdikit design, fdikit monitor (batch, follow), config validation."""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from fdikit import DataError
from fdikit.faults import Bias
from fdikit.monitor.config import build_monitor, load_config, map_channels, read_log
from fdikit.systems import two_mass

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "two-mass" / "monitor.toml"


def cli(*args, stdin=None):
    return subprocess.run([sys.executable, "-m", "fdikit.cli", *map(str, args)], capture_output=True,
                          text=True, input=stdin, timeout=600)


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    d = tmp_path_factory.mktemp("cfg")
    shutil.copy(EXAMPLE, d / "monitor.toml")
    out = cli("design", d / "monitor.toml", "--json")
    assert out.returncode == 0, out.stderr
    arts = json.loads(out.stdout)["artifacts"]
    assert set(arts) == {"observer", "hold", "design_report"} and all(Path(p).exists() for p in arts.values())
    s = two_mass.record([Bias("sensor:pos2", 0.012, start=4.0)], 1, 5)
    df = pd.DataFrame({"time": s.t, "F": s["force"][0], "P1": 1000 * s["pos1"][0], "P2": 1000 * s["pos2"][0]})
    df.loc[150, "P1"] = np.nan           # a dropout: flagged and held, not fatal
    df.to_csv(d / "log.csv", index=False)
    return d


def test_batch_monitor_detects_and_writes_outputs(workdir):
    out = cli("monitor", workdir / "log.csv", "--config", workdir / "monitor.toml", "--json",
              "--events", workdir / "ev.jsonl", "--stats", workdir / "st.parquet")
    assert out.returncode == 0, out.stderr
    lines = out.stdout.strip().splitlines()
    assert len(lines) == 1
    summary = json.loads(lines[0])
    assert summary["first_event"]["hypothesis"] == "sensor:pos2"
    assert 4.0 < summary["first_event"]["t"] < 4.5 and summary["n_events"] >= 1
    assert summary["invalid_samples"] == 1
    events = [json.loads(x) for x in (workdir / "ev.jsonl").read_text().splitlines()]
    assert events[0]["invalid"].startswith("channel 'pos1' has a non-finite value at sample 150")
    stats = pd.read_parquet(workdir / "st.parquet")
    assert {"t", "r:pos1", "r:pos2", "r:pos1:alarm", "valid"} <= set(stats.columns)
    assert not stats["valid"][150] and stats["valid"].sum() == len(stats) - 1
    assert np.isfinite(stats.drop(columns=["valid"]).to_numpy()).all()
    from fdikit.monitor.core import STATUS_NAMES

    assert STATUS_NAMES[stats["status"][150]] == "cannot_judge" and set(stats["status"]) <= {0, 1, 2}


def test_follow_mode_equals_batch(workdir):
    out = cli("monitor", workdir / "log.csv", "--config", workdir / "monitor.toml", "--events",
              workdir / "ev_follow_ref.jsonl")
    assert out.returncode == 0, out.stderr
    batch = [json.loads(x) for x in (workdir / "ev_follow_ref.jsonl").read_text().splitlines()]
    out = cli("monitor", "-", "--config", workdir / "monitor.toml", "--follow",
              stdin=(workdir / "log.csv").read_text())
    assert out.returncode == 0, out.stderr
    follow = [json.loads(x) for x in out.stdout.splitlines()]
    key = [(e.get("hypothesis"), e.get("invalid"), e["t"]) for e in batch]
    assert [(e.get("hypothesis"), e.get("invalid"), e["t"]) for e in follow] == key
    # and the statistics themselves: stream through the Python API against the batch run
    cfg = load_config(workdir / "monitor.toml")
    sig = map_channels(cfg, read_log(cfg, workdir / "log.csv"))
    a, b = build_monitor(cfg).run(sig), build_monitor(cfg).stream(sig)
    np.testing.assert_array_equal(a.statistics.values, b.statistics.values)


@pytest.mark.parametrize("text, match", [
    ("[channels.a]\nsource = 1\n[[generators]]\nartifact = 'x'\n", r"\[channels.a\].source must be str"),
    ("[channels.a]\nsorce = 'a'\n[[generators]]\nartifact = 'x'\n", "unknown key 'sorce'"),
    ("[chanels.a]\n", r"unknown section \[chanels\]"),
    ("[channels.a]\n", r"at least one \[\[generators\]\]"),
    ("[channels.a]\nscale = 0.0\n[[generators]]\nartifact = 'x'\n", "scale must be finite and non-zero"),
    ("[monitor]\non_invalid = 'ignore'\n[channels.a]\n[[generators]]\nartifact = 'x'\n", "on_invalid"),
    ("[channels.a\n", "not valid TOML"),
    ("[channels.a]\n[[generators]]\nartefact = 'x'\n", "unknown key 'artefact'"),
])
def test_bad_configs(tmp_path, text, match):
    p = tmp_path / "c.toml"
    p.write_text(text)
    with pytest.raises(DataError, match=match):
        load_config(p)


def test_artifact_for_other_channels_is_refused(workdir, tmp_path):
    text = (workdir / "monitor.toml").read_text().replace("[channels.pos2]", "[channels.height]")
    text = text.replace('artifacts = "designs"', f'artifacts = "{workdir / "designs"}"')
    p = tmp_path / "c.toml"
    p.write_text(text)
    with pytest.raises(DataError, match=r"reads channels \['pos2'\] that the config does not define"):
        build_monitor(load_config(p))
    out = cli("monitor", workdir / "nope.csv", "--config", p)
    assert out.returncode == 2 and "no such log file" in out.stderr


# ------------------------------------------------------------- issue 16: the new options, end to end
EPISODES = """
[log]
time_unit = "{unit}"
[monitor]
max_gap = 0.05
max_abs = 1e6
[decision]
channels = ["r:pos1:alarm", "r:pos2:alarm"]
level = 0.5
names = {{ "r:pos1:alarm" = "sensor:pos1", "r:pos2:alarm" = "sensor:pos2" }}
clear_level = 0.5
clear_after = 0.3
sizes = {{ "r:pos2:alarm" = "r:pos2" }}
"""


def _episode_config(workdir, tmp_path, unit="auto"):
    """The designed two-mass config with plausibility on pos1, gaps, max_abs and episode options."""
    d = tmp_path / "ep"
    shutil.copytree(workdir, d)
    text = (d / "monitor.toml").read_text()
    head, _, _ = text.partition("[decision]")
    head = head.replace("[monitor]\n", "[monitor]\nmax_gap = 0.05\nmax_abs = 1e6\n", 1)
    head = head.replace('time = "time"', f'time = "time"\ntime_unit = "{unit}"', 1)
    head = head.replace("scale = 0.001      # mm -> m", "scale = 0.001      # mm -> m\nmin = -2.0\nmax = 2.0",
                        1)
    dec = EPISODES.split("[decision]", 1)[1].replace("{{", "{").replace("}}", "}")
    (d / "monitor.toml").write_text(head + "[decision]" + dec)
    return d


def test_config_options_reach_the_monitor(workdir, tmp_path):
    d = _episode_config(workdir, tmp_path)
    cfg = load_config(d / "monitor.toml")
    mon = build_monitor(cfg)                      # the design is not stale: [design] is unchanged
    assert mon.max_gap == 0.05 and mon.max_abs == 1e6
    assert mon.decision.clear_after == 0.3 and mon.decision.size_channels == {"r:pos2:alarm": "r:pos2"}
    assert cfg.channels[1].plausibility == {"min": -2.0, "max": 2.0}


def test_batch_and_follow_write_the_same_episode_gap_and_invalid_records(workdir, tmp_path):
    """One log with a 0.1 s gap, an out-of-range pos1 sample (5 m, above max = 2 m) and a
    sensor:pos2 bias from 4 s (whose observer residual decays: the episode clears): batch and
    follow write identical records -- the gap, the held sample with its reason, the onset (with
    its size) and the cleared event."""
    d = _episode_config(workdir, tmp_path)
    df = pd.read_csv(workdir / "log.csv")
    df.loc[150, "P1"] = 5000.0                                   # 5 m after scaling: implausible
    df = df[(df.time < 0.5) | (df.time >= 0.6)]                  # a 0.1 s gap
    df.to_csv(d / "log.csv", index=False)
    b = cli("monitor", d / "log.csv", "--config", d / "monitor.toml", "--json", "--events", d / "b.jsonl",
            "--stats", d / "b.parquet")
    assert b.returncode == 0, b.stderr
    s = json.loads(b.stdout)
    f = cli("monitor", d / "log.csv", "--config", d / "monitor.toml", "--follow", "--events", d / "f.jsonl")
    assert f.returncode == 0, f.stderr
    recs = [json.loads(x) for x in (d / "b.jsonl").read_text().splitlines()]
    assert (d / "f.jsonl").read_text() == (d / "b.jsonl").read_text()
    assert [json.loads(x) for x in f.stdout.splitlines()] == recs          # printed as they happen
    gaps = [r for r in recs if r.get("gap")]
    assert len(gaps) == 1 and gaps[0]["t_start"] == pytest.approx(0.49) and gaps[0]["t"] == pytest.approx(0.6)
    held = [r for r in recs if "invalid" in r]
    assert len(held) == 1 and held[0]["t"] == pytest.approx(1.5) and "above max 2" in held[0]["invalid"]
    kinds = [(r["kind"], r["hypothesis"], r["episode"]) for r in recs if "kind" in r]
    assert kinds == [("onset", "sensor:pos2", 0), ("cleared", "sensor:pos2", 0)], recs
    onset = next(r for r in recs if r.get("kind") == "onset")
    assert 4.0 < onset["t"] < 4.5 and onset["size"] is not None and onset["size"] != 0
    assert s["n_gaps"] == 1 and s["n_cleared"] == 1 and s["status"]["cannot_judge"] == 1
    assert s["status"]["warmup"] > 0 and sum(s["status"].values()) == s["samples"]
    st = pd.read_parquet(d / "b.parquet")
    assert st["status"].tolist().count(1) == 1 and (st["status"] == 2).sum() == s["status"]["warmup"]


def test_epoch_nanosecond_log_gives_the_same_records_as_the_relative_one(workdir, tmp_path):
    d = _episode_config(workdir, tmp_path, unit="ns")
    df = pd.read_csv(workdir / "log.csv")
    rel = d / "rel.csv"
    df.to_csv(rel, index=False)
    ns = df.copy()
    ns["time"] = 1_700_000_000_123_456_789 + (df["time"] * 1e9).round().astype("int64")
    ns.to_csv(d / "ns.csv", index=False)
    out = {}
    for name, cfg_unit in (("rel", "s"), ("ns", "ns")):
        cfg = d / f"{name}.toml"
        text = (d / "monitor.toml").read_text()
        cfg.write_text(text.replace('time_unit = "ns"', f'time_unit = "{cfg_unit}"'))
        r = cli("monitor", d / f"{name}.csv", "--config", cfg, "--events", d / f"{name}.jsonl", "--json")
        assert r.returncode == 0, r.stderr
        f = cli("monitor", d / f"{name}.csv", "--config", cfg, "--follow", "--events", d / f"{name}.f.jsonl")
        assert f.returncode == 0, f.stderr
        text = (d / f"{name}.jsonl").read_text()
        assert (d / f"{name}.f.jsonl").read_text() == text
        out[name] = [{k: round(v, 9) if k in ("t", "t_start") else v for k, v in json.loads(x).items()}
                     for x in text.splitlines()]
    # the same records; times equal to 1e-9 s (the relative CSV holds floats like 2.2600000000000002,
    # the nanosecond clock the exact 2.26)
    assert out["ns"] == out["rel"] and any(r.get("kind") == "onset" for r in out["rel"])


def test_gap_gives_the_same_events_in_batch_gridded_and_follow_mode(workdir, tmp_path):
    """Issue 16, gap equivalence: one log with a 0.5 s gap (2.0-2.5 s) and a sensor:pos2 bias from
    4 s, run in batch (the gap is a time step), gridded ([log].rate = 100: NaN grid samples in the
    gap) and follow mode. All three give the same onset and cleared events, at the same times, and
    none of them between the gap and the fault (the old gridded run announced after the gap).
    The fault comes after the warm-up (the two-mass observer's 0.1 % settling time is 5.3 s): a
    fault that starts inside a warm-up is not judged until the warm-up ends."""
    d = _episode_config(workdir, tmp_path)
    s = two_mass.record([Bias("sensor:pos2", 0.012, start=12.0)], 1, 7, duration=16.0)
    df = pd.DataFrame({"time": s.t, "F": s["force"][0], "P1": 1000 * s["pos1"][0], "P2": 1000 * s["pos2"][0]})
    df = df[(df.time < 2.0) | (df.time >= 2.5)]
    df.to_csv(d / "log.csv", index=False)
    text = (d / "monitor.toml").read_text()
    (d / "grid.toml").write_text(text.replace('time = "time"', 'time = "time"\nrate = 100.0', 1))
    runs = {
        "batch": cli("monitor", d / "log.csv", "--config", d / "monitor.toml", "--events", d / "b.jsonl",
                     "--json"),
        "gridded": cli("monitor", d / "log.csv", "--config", d / "grid.toml", "--events", d / "g.jsonl",
                       "--json"),
        "follow": cli("monitor", d / "log.csv", "--config", d / "monitor.toml", "--follow",
                      "--events", d / "f.jsonl"),
    }
    events = {}
    for name, out in runs.items():
        assert out.returncode == 0, (name, out.stderr)
        recs = [json.loads(x) for x in (d / f"{name[0]}.jsonl").read_text().splitlines()]
        events[name] = [(r["kind"], r["hypothesis"], round(r["t"], 6)) for r in recs if "kind" in r]
    grid = json.loads(runs["gridded"].stdout)
    # the gap's grid samples are flagged, held only for the causal hold's max_gap = 3 periods
    assert grid["invalid_samples"] >= 47, grid
    assert events["batch"] == events["gridded"] == events["follow"], events
    onsets = [e for e in events["batch"] if e[0] == "onset"]
    assert onsets and onsets[0][1] == "sensor:pos2" and 12.0 < onsets[0][2] < 12.5, events
    assert not [e for e in events["batch"] if e[2] < 12.0], events
