"""Campaigns on Dask and local processes: the numbers of a local run, bit for bit, workers killed or not.

A LocalCluster of 2 worker processes (loopback only) serves the module; a 1-worker cluster checks
the other end. Worker deaths are real: SIGKILL of a worker process while it works.
"""

import json
import os
import signal
import threading
import time

import numpy as np
import pytest

pytest.importorskip("distributed")

from fdikit.evaluate import Engine, chunk_bounds, run_chunked
from fdikit.systems.abs.campaign import run_campaign

CAMPAIGN = dict(runs=3, nominal_runs=5, design_runs=7, seed=11, pfa=0.2, magnitudes="min")
ENV = {"NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}


def _clean(res) -> str:
    d = res.to_dict()
    d.pop("wall_seconds")
    return json.dumps(d, sort_keys=True)


@pytest.fixture(scope="module")
def cluster():
    with Engine(2, dask=True, env=ENV) as eng:
        yield eng


@pytest.fixture(scope="module")
def local_result():
    return _clean(run_campaign(**CAMPAIGN))


def _draws(start, stop, seed):
    """A toy campaign: run i draws from its own seed (what fdikit.sim does per run)."""
    return np.array([np.random.default_rng([seed, i]).normal(size=3) for i in range(start, stop)])


def _has_profiler(dask_worker):
    return "profile" in dask_worker.periodic_callbacks


def test_localcluster_workers_run_without_dask_profiler_unless_asked(cluster):
    """Dask's statistical profiler takes the interpreter lock from the running task every 10 ms:
    off in the workers of our LocalCluster by default (Engine(profile=False)), on when asked; the
    setting does not leak into this process's Dask config."""
    import dask

    assert not any(cluster.client.run(_has_profiler).values())
    with Engine(1, dask=True, env=ENV, profile=True) as eng:
        assert all(eng.client.run(_has_profiler).values())
    assert dask.config.get("distributed.worker.profile.enabled") is True


def test_chunk_bounds():
    assert chunk_bounds(7, 3) == [(0, 3), (3, 6), (6, 7)]
    assert chunk_bounds(0, 3) == []
    with pytest.raises(Exception, match="chunk size"):
        chunk_bounds(5, 0)


@pytest.mark.parametrize("chunk", [1, 4, 50])
def test_run_chunked_equals_local(cluster, chunk):
    ref = np.concatenate(run_chunked(_draws, 23, chunk_size=23, args=(5,)))
    out = np.concatenate(run_chunked(_draws, 23, chunk_size=chunk, args=(5,), engine=cluster))
    assert np.array_equal(out, ref)


@pytest.mark.parametrize("chunk", [2, 5])
def test_abs_campaign_on_two_workers_is_bitwise_local(cluster, local_result, chunk):
    res = run_campaign(**CAMPAIGN, engine=cluster, chunk_size=chunk)
    assert _clean(res) == local_result


@pytest.mark.slow  # a second cluster; the 2-worker tests above run in the fast suite
def test_abs_campaign_on_one_worker_is_bitwise_local(local_result):
    with Engine(1, dask=True, env=ENV) as eng:
        assert eng.n_workers == 1
        assert _clean(run_campaign(**CAMPAIGN, engine=eng, chunk_size=3)) == local_result


def test_worker_killed_mid_campaign_changes_nothing(cluster, local_result):
    """SIGKILL a worker process while it runs a chunk: Dask reruns the chunk, the numbers stay."""
    client = cluster.client
    pids = client.run(os.getpid)
    killed = []

    def killer():
        t_end = time.time() + 60
        while time.time() < t_end and not killed:
            busy = [w for w, tasks in client.processing().items() if tasks]
            if busy:
                time.sleep(0.3)  # let it get into the chunk
                os.kill(pids[busy[0]], signal.SIGKILL)
                killed.append(busy[0])
                return
            time.sleep(0.05)

    th = threading.Thread(target=killer)
    th.start()
    res = run_campaign(**CAMPAIGN, engine=cluster, chunk_size=1)
    th.join()
    assert killed, "no worker was killed"
    assert _clean(res) == local_result
    deadline = time.time() + 60  # the nanny restarts the worker for the next tests
    while len(client.scheduler_info(n_workers=-1)["workers"]) < 2 and time.time() < deadline:
        time.sleep(0.2)


def _die_once(arg):
    """Kill this worker process the first time it runs item 2 (a marker file remembers)."""
    item, marker = arg
    if item == 2 and not os.path.exists(marker):
        open(marker, "w").close()
        os.kill(os.getpid(), signal.SIGKILL)
    return item * item


def test_local_pool_survives_a_killed_worker(tmp_path):
    items = [(i, str(tmp_path / "died")) for i in range(6)]
    with Engine(2) as eng:
        out = dict(eng.map_unordered(_die_once, items))
    assert (tmp_path / "died").exists()  # a worker really died
    assert out == {i: i * i for i in range(6)}


def test_dask_reruns_the_task_of_a_killed_worker(cluster, tmp_path):
    items = [(i, str(tmp_path / "died")) for i in range(6)]
    out = dict(cluster.map_unordered(_die_once, items))
    assert (tmp_path / "died").exists()
    assert out == {i: i * i for i in range(6)}
