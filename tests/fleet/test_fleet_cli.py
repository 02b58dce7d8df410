"""`fdikit fleet`: logs generated from the real RAV4 minute (faults injected, time shifted), one corrupt.

Each log's events and summary equal a direct Monitor run over that log; a rerun skips committed
logs and redoes one whose output was removed; a corrupt log is an error record and the fleet goes
on; the same fleet on a Dask LocalCluster of 2 workers gives the same datasets.
"""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import cantools
import numpy as np
import pandas as pd
import pytest

from fdikit.commands.fleet import discover, path_fields, plan
from fdikit.io.decode import decode_message, read_blf_table, set_signal, write_blf_table
from fdikit.monitor.config import build_monitor, load_config, map_channels, read_log

from ..systems.car.rav4_example import DATA, rav4_config

pytestmark = pytest.mark.skipif(not (DATA / "drive.blf").exists(),
                                reason=f"real RAV4 data not found at {DATA}")


def cli(*args):
    return subprocess.run([sys.executable, "-m", "fdikit.cli", *map(str, args)], capture_output=True,
                          text=True, timeout=600)


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    d = tmp_path_factory.mktemp("fleet")
    rav4_config(d)
    ts, ids, pay, _ = read_blf_table(DATA / "drive.blf")
    db = cantools.database.load_file(str(DATA / "toyota_rav4.dbc"), strict=False)
    logs = d / "logs"

    def write(rel, crop=0.0, fault=None, shift=0.0):
        keep = ts - ts[0] >= crop
        t, fid, p = ts[keep] + shift, ids[keep], pay.take(keep)
        if fault is not None:
            mname, sname, bias, onset = fault
            msg = db.get_message_by_name(mname)
            sel = np.flatnonzero((fid == msg.frame_id) & (t - t[0] >= onset))
            v, _ = decode_message(msg, [sname], p.take(sel))
            p.matrix[sel] = set_signal(msg, sname, p.take(sel), v[:, 0] + bias).matrix
        (logs / rel).parent.mkdir(parents=True, exist_ok=True)
        return write_blf_table(logs / rel, t, fid, p)

    write("veh1/a.blf")
    write("veh1/b.blf", fault=("KINEMATICS", "YAW_RATE", 5.0, 30.0), shift=86400.0)
    write("veh2/c.blf", crop=5.0, fault=("KINEMATICS", "ACCEL_Y", -1.5, 20.0), shift=7200.0)
    raw = (logs / "veh1" / "a.blf").read_bytes()
    (logs / "veh2" / "bad.blf").write_bytes(raw[: len(raw) // 2])  # truncated in a container
    (logs / "veh2" / "notes.md").write_text("not a log\n")
    return d


def direct(cfg_path, log):
    cfg = load_config(cfg_path)
    sig = map_channels(cfg, read_log(cfg, log))
    res = build_monitor(cfg).run(sig)
    return sig, res


def datasets(out):
    s = pd.read_parquet(out / "summaries")
    e = pd.read_parquet(out / "events")
    return (s.sort_values("log_id").reset_index(drop=True),
            e.sort_values(["log_id", "sample"]).reset_index(drop=True))


@pytest.fixture(scope="module")
def first_run(fleet):
    out = fleet / "out"
    r = cli("fleet", fleet / "logs", "--config", fleet / "monitor.toml", "--out", out, "--json",
            "--processes", "2")
    assert r.returncode == 0, r.stderr
    assert len(r.stdout.strip().splitlines()) == 1 and r.stderr == ""  # one JSON object, no progress bar
    return json.loads(r.stdout), out


def test_fleet_writes_what_a_direct_run_gives(fleet, first_run):
    rep, out = first_run
    assert (rep["logs"], rep["processed"], rep["ok"], rep["errors"], rep["skipped"]) == (4, 4, 3, 1, 0)
    s, e = datasets(out)
    assert list(s["log_id"]) == ["veh1/a.blf", "veh1/b.blf", "veh2/bad.blf", "veh2/c.blf"]
    assert list(s["vehicle"].astype(str)) == ["veh1", "veh1", "veh2", "veh2"]
    assert list(s["route"]) == ["a", "b", "bad", "c"]
    n_episodes = 0
    for _, row in s[s["status"] == "ok"].iterrows():
        sig, res = direct(fleet / "monitor.toml", row["path"])
        assert row["samples"] == sig.n_samples and row["invalid_samples"] == len(res.invalid)
        assert row["duration_s"] == pytest.approx(float(sig.t[-1] - sig.t[0]), abs=0)
        mine = e[e["log_id"] == row["log_id"]]
        onsets, cleared = mine[mine["kind"] == "onset"], mine[mine["kind"] == "cleared"]
        assert [(ev.k, ev.t, ev.hypothesis, ev.value) for ev in res.events] == \
            list(zip(onsets["sample"], onsets["t"], onsets["hypothesis"], onsets["value"]))
        assert [(ev.k, ev.hypothesis, ev.episode) for ev in res.cleared] == \
            list(zip(cleared["sample"], cleared["hypothesis"], cleared["episode"]))
        assert row["episodes"] == len(res.events) and row["cleared"] == len(res.cleared)
        assert row["gaps"] == len(res.gaps)
        assert row["cannot_judge_samples"] + row["warmup_samples"] == int((res.status[0] != 0).sum())
        n_episodes += len(res.events)
    assert n_episodes >= 1  # the injected faults are announced (the comparison is not of empty lists)
    assert s.loc[s["log_id"] == "veh1/b.blf", "episodes"].item() >= 1


def test_corrupt_log_is_an_error_record_and_the_fleet_goes_on(first_run):
    rep, out = first_run
    s, _ = datasets(out)
    bad = s[s["status"] == "error"]
    assert list(bad["log_id"]) == ["veh2/bad.blf"]
    msg = bad["error"].item()
    assert "bad.blf" in msg and "truncated" in msg
    assert rep["error_records"][0]["error"] == msg


def test_rerun_skips_committed_and_redoes_removed(fleet, first_run):
    _, out = first_run
    before = datasets(out)
    args = ("fleet", fleet / "logs", "--config", fleet / "monitor.toml", "--out", out, "--json",
            "--processes", "1")
    rep = json.loads(cli(*args).stdout)
    assert (rep["skipped"], rep["processed"]) == (4, 0)
    # a log whose summary is gone (its worker died before the commit) and one whose events are gone
    summ = next((out / "summaries" / "vehicle=veh1").glob("veh1_b_blf-*.parquet"))
    summ.unlink()
    ev = next((out / "events" / "vehicle=veh2").glob("veh2_c_blf-*.parquet"))
    ev.unlink()
    (out / "events" / "vehicle=veh1" / ".tmp-deadbeef-x.parquet").write_bytes(b"partial")
    rep = json.loads(cli(*args).stdout)
    assert (rep["skipped"], rep["processed"], rep["temporary_files_removed"]) == (2, 2, 1)
    after = datasets(out)
    cols = ["log_id", "status", "samples", "invalid_samples", "episodes", "first_event_t", "duration_s"]
    pd.testing.assert_frame_equal(after[0][cols], before[0][cols])
    pd.testing.assert_frame_equal(after[1], before[1])


def test_same_fleet_on_a_dask_localcluster(fleet, first_run):
    _, out_local = first_run
    out = fleet / "out_dask"
    r = cli("fleet", fleet / "logs", "--config", fleet / "monitor.toml", "--out", out, "--json",
            "--workers", "2")
    assert r.returncode == 0, r.stderr
    rep = json.loads(r.stdout)
    assert rep["engine"]["kind"] == "dask" and rep["engine"]["workers"] == 2
    assert (rep["ok"], rep["errors"]) == (3, 1)
    a, b = datasets(out_local), datasets(out)
    cols = ["log_id", "status", "error", "samples", "invalid_samples", "episodes", "first_event_t",
            "max_statistics"]
    pd.testing.assert_frame_equal(a[0][cols], b[0][cols])
    pd.testing.assert_frame_equal(a[1], b[1])


def test_inputs_manifest_and_path_fields(fleet, tmp_path):
    logs = fleet / "logs"
    found = [str(r) for _, r in discover([str(logs)])]
    assert found == ["veh1/a.blf", "veh1/b.blf", "veh2/bad.blf", "veh2/c.blf"]  # notes.md is no log
    assert [str(r) for _, r in discover([str(logs / "veh*" / "*.blf")])] == found
    lst = tmp_path / "logs.txt"
    lst.write_text("# two logs\n" + "\n".join(str(p) for p in [logs / "veh1/a.blf", logs / "veh2/c.blf"])
                   + "\n")
    assert [p.name for p, _ in discover([str(lst)])] == ["a.blf", "c.blf"]
    man = tmp_path / "manifest.csv"
    man.write_text(f"path,vehicle,route,driver\n{logs / 'veh1/a.blf'},RAV4-7,highway-101,kim\n")
    tasks = {t.log_id: t for t in plan([str(logs)], fleet / "monitor.toml", tmp_path / "o", manifest=man)}
    a, c = tasks["veh1/a.blf"], tasks["veh2/c.blf"]
    assert (a.vehicle, a.route, a.fields) == ("RAV4-7", "highway-101", {"driver": "kim"})
    assert (c.vehicle, c.route) == ("veh2", "c")
    assert path_fields(Path("x/2024/v3/r.blf"), "{date}/{vehicle}/{route}") == \
        {"route": "r", "vehicle": "v3", "date": "2024"}
    r = cli("fleet", tmp_path / "nothing-here", "--config", fleet / "monitor.toml", "--out", tmp_path / "o")
    assert r.returncode == 2 and "nothing-here" in r.stderr


def test_fleet_keeps_logs_out_of_the_output(fleet, tmp_path):
    """The output directory inside a searched directory is not searched."""
    d = tmp_path / "root"
    shutil.copytree(fleet / "logs" / "veh1", d / "veh1")
    shutil.copytree(fleet / "out", d / "out")
    assert [str(r) for _, r in discover([str(d)], exclude=d / "out")] == ["veh1/a.blf", "veh1/b.blf"]
