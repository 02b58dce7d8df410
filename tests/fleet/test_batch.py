"""`fdikit fleet` tasks that are batches of logs (issue 19): each log is still committed on its own.

Logs generated from the real RAV4 minute (cropped to different lengths). A batch returns one
summary row per log; a batch rerun after its worker died (simulated: the first attempt stops
after two commits) skips the logs it committed and does the rest; a rerun of the fleet skips
every committed log and redoes a removed one; a corrupt log in a batch is an error record and the
batch goes on; the in-memory Parquet writer's files read back as the default writer's do.
"""

import json
import shutil
import subprocess
import sys

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from fdikit import fleet
from fdikit.fleet import batch as fleet_batch
from fdikit.fleet import batch_size, batches, is_done, plan, process_log, process_logs, run_fleet
from fdikit.fleet import process as fleet_process
from fdikit.io.decode import read_blf_table, write_blf_table

from ..systems.car.rav4_example import DATA, rav4_config

pytestmark = pytest.mark.skipif(not (DATA / "drive.blf").exists(),
                                reason=f"real RAV4 data not found at {DATA}")
N_LOGS = 7


@pytest.fixture(scope="module")
def fleet_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("fleet_batch")
    rav4_config(d)
    ts, ids, pay, _ = read_blf_table(DATA / "drive.blf")
    for i in range(N_LOGS):
        keep = (ts - ts[0] >= 2.0 * i) & (ts - ts[0] <= 30.0 + 4.0 * i)
        (d / "logs" / f"veh{i % 2}").mkdir(parents=True, exist_ok=True)
        write_blf_table(d / "logs" / f"veh{i % 2}" / f"r{i}.blf", ts[keep] + 3600.0 * i, ids[keep],
                        pay.take(keep))
    raw = (d / "logs" / "veh0" / "r0.blf").read_bytes()
    (d / "logs" / "veh1" / "r9-bad.blf").write_bytes(raw[: len(raw) // 3])  # truncated
    return d


def _tasks(fleet_dir, out):
    return plan([str(fleet_dir / "logs")], fleet_dir / "monitor.toml", out)


def _summaries(out):
    return pd.read_parquet(out / "summaries").sort_values("log_id").reset_index(drop=True)


def test_batch_size():
    assert batch_size(0, 2) == 1 and batch_size(1, 1) == 1
    assert batch_size(200, 2) == 16 and batch_size(200, 1) == 16 and batch_size(10**6, 4) == 16
    assert batch_size(12, 1) == 12  # one worker: nobody to balance against
    assert batch_size(50, 8) == 2 and batch_size(20, 8) == 1  # the end of a run: small tasks
    # guided: every log once, in order, sizes never growing, the last tasks one log each
    for n, w in ((200, 2), (1000, 4), (37, 3), (5, 2)):
        b = batches(list(range(n)), w)
        assert [x for t in b for x in t] == list(range(n))
        sizes = [len(t) for t in b]
        assert sizes == sorted(sizes, reverse=True) and max(sizes) <= 16 and sizes[-w:] == [1] * w


def test_batch_commits_every_log_and_equals_one_task_per_log(fleet_dir, tmp_path):
    one = _tasks(fleet_dir, tmp_path / "single")
    rows_single = [process_log(t) for t in one]
    batched = _tasks(fleet_dir, tmp_path / "batched")
    rows = process_logs(batched)
    assert [r["log_id"] for r in rows] == [t.log_id for t in batched]
    assert all(is_done(t) for t in batched)
    assert [r["status"] for r in rows].count("error") == 1  # the truncated log, and the batch went on
    bad = next(r for r in rows if r["status"] == "error")
    assert "r9-bad.blf" in bad["error"] and "truncated" in bad["error"]
    a, b = _summaries(tmp_path / "single"), _summaries(tmp_path / "batched")
    cols = ["log_id", "vehicle", "route", "status", "error", "samples", "invalid_samples", "episodes",
            "cleared", "duration_s", "t0", "max_statistics", "hypotheses"]
    pd.testing.assert_frame_equal(a[cols], b[cols])
    ea, eb = (pd.read_parquet(tmp_path / k / "events").sort_values(["log_id", "sample"])
              .reset_index(drop=True) for k in ("single", "batched"))
    pd.testing.assert_frame_equal(ea, eb)
    assert [r["samples"] for r in rows] == [r["samples"] for r in rows_single]


class _Died(BaseException):
    """The worker process of a batch ended (a BaseException: no error record catches it)."""


def test_batch_rerun_after_its_worker_died_skips_what_it_committed(fleet_dir, tmp_path, monkeypatch):
    tasks = _tasks(fleet_dir, tmp_path / "out")
    done = []
    real = fleet_process.process_log

    def dying(task):
        if len(done) == 2:
            raise _Died()
        done.append(task.log_id)
        return real(task)

    monkeypatch.setattr(fleet_process, "process_log", dying)
    with pytest.raises(_Died):
        process_logs(tasks)
    assert [is_done(t) for t in tasks] == [True, True] + [False] * (len(tasks) - 2)
    first = {t.log_id: pq.ParquetFile(next((tmp_path / "out" / "summaries").rglob(f"{t.part}.parquet")))
             .read().to_pylist()[0] for t in tasks[:2]}
    redone = []
    monkeypatch.setattr(fleet_process, "process_log", lambda task: redone.append(task.log_id) or real(task))
    rows = process_logs(tasks)  # the rerun of the lost task
    assert redone == [t.log_id for t in tasks[2:]]
    assert [r["log_id"] for r in rows] == [t.log_id for t in tasks]
    for t, r in zip(tasks[:2], rows[:2]):  # the committed rows, as they were written
        assert {k: v for k, v in r.items() if k != "vehicle"} == first[t.log_id]
        assert r["vehicle"] == t.vehicle


class _InProcess:
    """An engine that runs the tasks here; the first attempt of the first task dies after one commit
    and is rerun, as Dask reruns the task of a dead worker."""

    n_workers = 2

    def __init__(self, monkeypatch):
        self.monkeypatch = monkeypatch
        self.n_tasks = 0

    def map_unordered(self, fn, items):
        real = fleet_process.process_log
        calls = []

        def dying(task):
            if len(calls) == 1:
                raise _Died()
            calls.append(task)
            return real(task)

        for i, item in enumerate(items):
            self.n_tasks += 1
            if i == 0:
                self.monkeypatch.setattr(fleet_process, "process_log", dying)
                with pytest.raises(_Died):
                    fn(item)
                self.monkeypatch.setattr(fleet_process, "process_log", real)
            yield i, fn(item)


def test_run_fleet_batches_and_reruns(fleet_dir, tmp_path, monkeypatch):
    tasks = _tasks(fleet_dir, tmp_path / "out")
    monkeypatch.setattr(fleet_batch, "batch_size", lambda n, w: 3)
    eng = _InProcess(monkeypatch)
    rep = run_fleet(tasks, eng)
    assert eng.n_tasks == -(-len(tasks) // 3)
    assert (rep["logs"], rep["processed"], rep["ok"], rep["errors"], rep["skipped"]) == \
        (len(tasks), len(tasks), len(tasks) - 1, 1, 0)
    assert sorted(_summaries(tmp_path / "out")["log_id"]) == sorted(t.log_id for t in tasks)
    # a rerun skips everything; one removed summary and one removed event file are redone
    rep = run_fleet(tasks, _InProcess(monkeypatch))
    assert (rep["skipped"], rep["processed"]) == (len(tasks), 0)
    before = _summaries(tmp_path / "out")
    next((tmp_path / "out" / "summaries").rglob(f"{tasks[1].part}.parquet")).unlink()
    next((tmp_path / "out" / "events").rglob(f"{tasks[4].part}.parquet")).unlink()
    rep = run_fleet(tasks, _InProcess(monkeypatch))
    assert (rep["skipped"], rep["processed"]) == (len(tasks) - 2, 2)
    after = _summaries(tmp_path / "out")
    cols = ["log_id", "status", "samples", "episodes", "max_statistics"]
    pd.testing.assert_frame_equal(after[cols], before[cols])
    redone = after["log_id"].isin([tasks[1].log_id, tasks[4].log_id])
    assert (after.loc[redone, "wall_s"].to_numpy() != before.loc[redone, "wall_s"].to_numpy()).all()
    assert (after.loc[~redone, "wall_s"].to_numpy() == before.loc[~redone, "wall_s"].to_numpy()).all()


def test_retry_errors_in_batches(fleet_dir, tmp_path):
    tasks = _tasks(fleet_dir, tmp_path / "out")
    process_logs(tasks)
    before = _summaries(tmp_path / "out").set_index("log_id")
    rows = process_logs(tasks, retry_errors=True)
    after = _summaries(tmp_path / "out").set_index("log_id")
    # the error record is redone (an error again), the ok logs are read back, not redone
    assert len(rows) == len(tasks) and [r["status"] for r in rows].count("error") == 1
    for r in rows:
        same = after.loc[r["log_id"], "wall_s"] == before.loc[r["log_id"], "wall_s"]
        assert same == (r["status"] == "ok")


def test_small_table_writer_reads_back_as_the_default_writer(tmp_path):
    summary, events = fleet._schemas()
    assert fleet._schemas()[0] is summary  # built once per process
    rows = [{"log_id": f"v/{i}.blf", "route": str(i), "t": 0.5 * i, "sample": i, "run": 0,
             "hypothesis": "yaw_rate" if i % 2 else None, "value": np.float64(0.1 * i), "kind": "onset",
             "episode": i, "size": None} for i in range(5)]
    table = pa.Table.from_pylist(rows, schema=events)
    fleet._commit(table, tmp_path / "a" / "vehicle=x" / "p.parquet")
    pq.write_table(table, tmp_path / "b.parquet")
    assert not list((tmp_path / "a").rglob(".tmp-*"))
    got = pq.read_table(tmp_path / "a" / "vehicle=x" / "p.parquet")
    assert got.schema == table.schema and got.equals(table)
    pd.testing.assert_frame_equal(pd.read_parquet(tmp_path / "a" / "vehicle=x" / "p.parquet"),
                                  pd.read_parquet(tmp_path / "b.parquet"))
    ds = pd.read_parquet(tmp_path / "a")
    assert list(ds["vehicle"].astype(str)) == ["x"] * 5
    empty = pa.Table.from_pylist([], schema=events)
    fleet._commit(empty, tmp_path / "a" / "vehicle=y" / "q.parquet")
    assert pq.read_table(tmp_path / "a" / "vehicle=y" / "q.parquet").num_rows == 0
    # a directory removed behind the writer's back is made again
    shutil.rmtree(tmp_path / "a")
    fleet._commit(table, tmp_path / "a" / "vehicle=x" / "p.parquet")
    assert pq.read_table(tmp_path / "a" / "vehicle=x" / "p.parquet").equals(table)


def test_cli_fleet_with_batches_on_local_processes(fleet_dir, tmp_path):
    out = tmp_path / "out"
    r = subprocess.run([sys.executable, "-m", "fdikit.cli", "fleet", str(fleet_dir / "logs"), "--config",
                        str(fleet_dir / "monitor.toml"), "--out", str(out), "--json", "--processes", "2"],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    rep = json.loads(r.stdout)
    assert (rep["processed"], rep["ok"], rep["errors"]) == (N_LOGS + 1, N_LOGS, 1)
    s = _summaries(out)
    assert len(s) == N_LOGS + 1 and s["worker"].nunique() >= 1


def _worker_env():
    import os

    return {k: os.environ.get(k) for k in fleet.WORKER_ENV}


def test_fleet_workers_get_the_allocator_options_before_they_start():
    """The MALLOC_* options reach a LocalCluster's workers (set before they are spawned, as glibc
    needs) and the pool's workers; this process's own environment does not keep them."""
    import os

    from fdikit.evaluate.distributed import Engine, _apply_malloc_options

    before = {k: os.environ.get(k) for k in ("MALLOC_ARENA_MAX", "MALLOC_MMAP_THRESHOLD_")}
    with Engine(1, dask=True, env=fleet.WORKER_ENV) as eng:
        seen = next(iter(eng.client.run(_worker_env).values()))
    assert seen == fleet.WORKER_ENV
    assert {k: os.environ.get(k) for k in before} == before
    with Engine(1, env=fleet.WORKER_ENV) as eng:
        assert next(eng.map_unordered(_call, [_worker_env]))[1] == fleet.WORKER_ENV
    _apply_malloc_options({"MALLOC_TOP_PAD_": "not a number"})  # ignored, never an error


def _call(fn):
    return fn()
