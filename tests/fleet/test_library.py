"""The fleet as a library (issue 25): ``fdikit.fleet`` without the CLI.

* a fleet run from Python alone, in a fresh interpreter that never imports ``fdikit.commands``,
  writes the event files the command writes, byte for byte, and the same summaries (but for
  the timings and the worker's name);
* resume through the library: a rerun skips the committed logs, a removed summary is redone, and
  ``retry_errors`` redoes the error records only;
* the in-process engine and the report.

The logs are CSV logs of the two-mass example (simulated, with sensor faults), so the test needs
no external data; one log is garbage and becomes an error record.
"""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from fdikit import DataError, fleet
from fdikit.faults import Bias
from fdikit.monitor.config import load_config, run_design
from fdikit.systems import two_mass

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "two-mass" / "monitor.toml"
TIMING = ["load_s", "monitor_s", "write_s", "wall_s", "worker"]


@pytest.fixture(scope="module")
def fleet_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("fleet_library")
    shutil.copy(EXAMPLE, d / "monitor.toml")
    run_design(load_config(d / "monitor.toml"))
    for i in range(5):
        faults = [Bias("sensor:pos2", 0.012, start=4.0)] if i % 2 else []
        s = two_mass.record(faults, 1, 10 + i)
        df = pd.DataFrame({"time": s.t, "F": s["force"][0], "P1": 1000 * s["pos1"][0],
                           "P2": 1000 * s["pos2"][0]})
        if i == 3:
            df.loc[200, "P1"] = np.nan  # a held sample
        (d / "logs" / f"veh{i % 2}").mkdir(parents=True, exist_ok=True)
        df.to_csv(d / "logs" / f"veh{i % 2}" / f"r{i}.csv", index=False)
    (d / "logs" / "veh1" / "r9-bad.csv").write_text("this,is\nnot a log\n")
    return d


def _table(out, kind):
    return pd.read_parquet(out / kind).sort_values("log_id", kind="stable").reset_index(drop=True)


def test_fleet_from_python_alone_equals_the_command(fleet_dir, tmp_path):
    lib, cli = tmp_path / "lib", tmp_path / "cli"
    code = f"""
import json, sys
import fdikit.fleet
report = fdikit.fleet.run([{str(fleet_dir / 'logs')!r}], {str(fleet_dir / 'monitor.toml')!r}, {str(lib)!r},
                          in_process=True)
assert not any(m == "fdikit.commands" or m.startswith("fdikit.commands.") or m == "fdikit.cli"
               for m in sys.modules), sorted(m for m in sys.modules if m.startswith("fdikit.c"))
print(json.dumps(report))
"""
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    rep = json.loads(r.stdout)
    assert (rep["logs"], rep["processed"], rep["ok"], rep["errors"], rep["skipped"]) == (6, 6, 5, 1, 0)
    assert rep["engine"] == {"kind": "in-process", "workers": 1} and rep["episodes"] >= 2
    assert "r9-bad.csv" in rep["error_records"][0]["error"]
    c = subprocess.run([sys.executable, "-m", "fdikit.cli", "fleet", str(fleet_dir / "logs"), "--config",
                        str(fleet_dir / "monitor.toml"), "--out", str(cli), "--json", "--processes", "2"],
                       capture_output=True, text=True, timeout=600)
    assert c.returncode == 0, c.stderr
    crep = json.loads(c.stdout)
    assert {k: v for k, v in crep.items() if k not in ("wall_seconds", "task_seconds", "load_decode_share",
                                                       "engine", "out", "datasets")} == \
        {k: v for k, v in rep.items() if k not in ("wall_seconds", "task_seconds", "load_decode_share",
                                                   "engine", "out", "datasets")}
    # the event files byte for byte, the summaries but for timings and worker
    files = sorted(p.relative_to(lib) for p in (lib / "events").rglob("*.parquet"))
    assert len(files) == 6
    assert files == sorted(p.relative_to(cli) for p in (cli / "events").rglob("*.parquet"))
    for f in files:
        assert (lib / f).read_bytes() == (cli / f).read_bytes(), f
    pd.testing.assert_frame_equal(_table(lib, "summaries").drop(columns=TIMING),
                                  _table(cli, "summaries").drop(columns=TIMING))
    assert _table(lib, "events")["kind"].tolist().count("onset") == rep["episodes"]


def test_resume_and_retry_through_the_library(fleet_dir, tmp_path):
    out = tmp_path / "out"
    first = fleet.run([str(fleet_dir / "logs")], fleet_dir / "monitor.toml", out, in_process=True)
    assert (first["processed"], first["errors"]) == (6, 1)
    again = fleet.run([str(fleet_dir / "logs")], fleet_dir / "monitor.toml", out, in_process=True)
    assert (again["skipped"], again["processed"]) == (6, 0)
    before = _table(out, "summaries")
    tasks = fleet.plan([str(fleet_dir / "logs")], fleet_dir / "monitor.toml", out)
    victim = next(t for t in tasks if t.log_id == "veh0/r2.csv")
    next((out / "summaries").rglob(f"{victim.part}.parquet")).unlink()
    (out / "events" / "vehicle=veh0" / ".tmp-dead-worker.parquet").write_bytes(b"half a file")
    rep = fleet.run([str(fleet_dir / "logs")], fleet_dir / "monitor.toml", out, in_process=True)
    assert (rep["skipped"], rep["processed"], rep["temporary_files_removed"]) == (5, 1, 1)
    after = _table(out, "summaries")
    pd.testing.assert_frame_equal(after.drop(columns=TIMING), before.drop(columns=TIMING))
    redone = (after["log_id"] == "veh0/r2.csv").to_numpy()
    assert (after["wall_s"].to_numpy() != before["wall_s"].to_numpy()).tolist() == redone.tolist()
    rep = fleet.run([str(fleet_dir / "logs")], fleet_dir / "monitor.toml", out, in_process=True,
                    retry_errors=True)
    assert (rep["skipped"], rep["processed"], rep["errors"]) == (5, 1, 1)
    assert rep["error_records"][0]["log_id"] == "veh1/r9-bad.csv"


def test_planned_fleet_on_the_in_process_engine(fleet_dir, tmp_path):
    tasks = fleet.plan([str(fleet_dir / "logs")], fleet_dir / "monitor.toml", tmp_path / "out",
                       template="{vehicle}/{route}")
    assert [(t.vehicle, t.route) for t in tasks][:2] == [("veh0", "r0"), ("veh0", "r2")]
    assert not any(fleet.is_done(t) for t in tasks)
    with fleet.make_engine(len(tasks), in_process=True) as engine:
        rep = fleet.run_fleet(tasks, engine)
    assert all(fleet.is_done(t) for t in tasks) and rep["processed"] == len(tasks)
    assert not all(fleet.is_done(t, retry_errors=True) for t in tasks)
    rows = fleet.process_logs(tasks)  # all committed: the rows are read back, not redone
    assert [r["log_id"] for r in rows] == [t.log_id for t in tasks]
    assert fleet.summarise(rows, logs=len(tasks), skipped=0, wall_seconds=1.0)["ok"] == rep["ok"]


def test_bad_options_refused_before_any_log(fleet_dir, tmp_path):
    cfg = fleet_dir / "monitor.toml"
    with pytest.raises(DataError, match="no such config file"):
        fleet.run([str(fleet_dir / "logs")], tmp_path / "none.toml", tmp_path / "out")
    with pytest.raises(DataError, match="choose one of"):
        fleet.run([str(fleet_dir / "logs")], cfg, tmp_path / "out", processes=2, workers=2)
    with pytest.raises(DataError, match="must be >= 1"):
        fleet.check_options(cfg, processes=0)
    assert not (tmp_path / "out").exists()
    (tmp_path / "empty").mkdir()
    with pytest.raises(DataError, match="no log files found"):
        fleet.run([str(tmp_path / "empty")], cfg, tmp_path / "out", in_process=True)
