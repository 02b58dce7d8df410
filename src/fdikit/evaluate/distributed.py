"""Campaigns and fleets beyond one process: tasks on local processes or on a Dask distributed cluster.

fdikit does not schedule anything itself. An :class:`Engine` hands tasks to an existing engine:

* ``Engine()`` / ``Engine(workers=N)`` without Dask options: a :class:`concurrent.futures.
  ProcessPoolExecutor` of N local processes (default: the number of cores); when a worker process
  dies the pool breaks, and the engine resubmits every unfinished task to a fresh pool (at most
  ``retries`` times per task), so a killed worker changes nothing but the wall time;
* ``Engine(workers=N, dask=True)``: a :class:`distributed.LocalCluster` of N single-threaded
  worker processes on the loopback interface;
* ``Engine(scheduler="tcp://host:8786")``: a running Dask cluster. Dask's scheduler reruns the
  tasks of a worker that died on another worker (up to its ``allowed-failures``).

Two ways to use it:

* :meth:`Engine.map_unordered` runs ``fn(item)`` for every item and yields ``(index, result)`` as
  tasks finish (the fleet: one task per log).
* :func:`run_chunked` splits runs ``0 .. n-1`` into chunks, runs ``fn(start, stop, *args)`` per
  chunk as one task and returns the chunk results in run order (Monte Carlo campaigns). When
  ``fn`` draws each run from its own seed (``fdikit.sim``'s per-run seeds: run i is the same
  alone or in a batch), the concatenated result is bitwise the same for any number of workers,
  any chunk size and any worker lost and rerun on the way; ``engine=None`` runs the chunks in
  this process, the reference the tests compare against.

Examples
--------
>>> import numpy as np
>>> def square(start, stop):
...     return np.arange(start, stop) ** 2
>>> parts = run_chunked(square, 10, chunk_size=4)          # in this process
>>> [p.tolist() for p in parts]
[[0, 1, 4, 9], [16, 25, 36, 49], [64, 81]]
"""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
import os
import sys
from collections.abc import Callable, Iterable, Iterator, Sequence
from typing import Any

from ..errors import DataError

__all__ = ["Engine", "chunk_bounds", "run_chunked"]


def chunk_bounds(n: int, chunk_size: int) -> list[tuple[int, int]]:
    """``[(start, stop), ...]`` covering ``range(n)`` in chunks of at most ``chunk_size`` runs.

    Examples
    --------
    >>> chunk_bounds(5, 2)
    [(0, 2), (2, 4), (4, 5)]
    """
    if not isinstance(chunk_size, int) or chunk_size < 1:
        raise DataError(f"chunk size must be a positive number of runs, got {chunk_size!r}")
    if n < 0:
        raise DataError(f"number of runs must be >= 0, got {n}")
    return [(a, min(a + chunk_size, n)) for a in range(0, n, chunk_size)]


#: glibc's allocator options (``mallopt`` parameter numbers) that :class:`Engine` applies in its
#: workers when ``env`` names them, as the C library would read them at process start.
_MALLOC_OPTIONS = {"MALLOC_TRIM_THRESHOLD_": -1, "MALLOC_TOP_PAD_": -2, "MALLOC_MMAP_THRESHOLD_": -3,
                   "MALLOC_ARENA_MAX": -8}


def _set_env(env: dict[str, str]) -> None:
    """Set ``env`` in this (worker) process, and apply the glibc allocator options it names."""
    os.environ.update(env)
    _apply_malloc_options(env)


def _apply_malloc_options(env: dict[str, str]) -> None:
    """``mallopt`` the ``MALLOC_*_`` options of ``env`` in this process (glibc only; elsewhere no-op).

    glibc reads these variables once, when a process starts; a worker started before they were
    set (a pool's initializer, a running Dask cluster) gets them here instead.
    """
    opts = {k: v for k, v in env.items() if k in _MALLOC_OPTIONS}
    if not opts or not sys.platform.startswith("linux"):
        return
    try:
        import ctypes

        libc = ctypes.CDLL("libc.so.6")
        for k, v in opts.items():
            libc.mallopt(_MALLOC_OPTIONS[k], int(v))
    except (OSError, AttributeError, ValueError):  # not glibc, or a value that is no number
        pass


class Engine:
    """Where tasks run: local processes, a local Dask cluster, or a Dask scheduler.

    Parameters
    ----------
    workers : int, optional
        Worker processes (local pool or LocalCluster); default the number of cores.
    scheduler : str, optional
        Address of a running Dask scheduler (``"tcp://127.0.0.1:8786"``); ``workers`` is then
        not used.
    dask : bool
        With ``workers``: a :class:`distributed.LocalCluster` instead of a process pool.
    retries : int
        Local pool: how often a task is resubmitted after its worker process died.
    env : dict, optional
        Environment variables set in every worker before it runs a task (e.g.
        ``{"NUMBA_NUM_THREADS": "1"}`` so that one worker uses one core). glibc's allocator
        options among them (``MALLOC_TRIM_THRESHOLD_``, ``MALLOC_MMAP_THRESHOLD_``,
        ``MALLOC_TOP_PAD_``, ``MALLOC_ARENA_MAX``) are set before a LocalCluster's workers
        start and applied with ``mallopt`` in the workers of a pool or a running cluster.
    preload : sequence of str
        Local pool: modules the fork server imports once for all its workers.
    profile : bool
        LocalCluster: keep Dask's statistical profiler in the workers (the dashboard's profile
        page). Off by default: it samples the task thread's stack every 10 ms, and every sample
        takes the interpreter lock from the running task -- a fifth of a fleet task's time on the
        RAV4 minute (benchmarks/bench_fleet.py: 26.7 -> 21.7 ms per log on one worker). A running
        cluster (``scheduler``) keeps its own setting (``distributed.worker.profile.enabled``).

    Notes
    -----
    Use it as a context manager: the pool or cluster is shut down on exit.
    """

    def __init__(self, workers: int | None = None, *, scheduler: str | None = None, dask: bool = False,
                 retries: int = 3, env: dict[str, str] | None = None, preload: Sequence[str] = (),
                 profile: bool = False):
        if workers is not None and (not isinstance(workers, int) or workers < 1):
            raise DataError(f"workers must be a positive number of processes, got {workers!r}")
        self.scheduler = scheduler
        self.kind = "dask" if (scheduler or dask) else "local"
        self.workers = workers or os.cpu_count() or 1
        self.retries = int(retries)
        self.env = dict(env or {})
        self.preload = tuple(preload)
        self.profile = bool(profile)
        self._pool: cf.ProcessPoolExecutor | None = None
        self.client = None
        self.cluster = None

    # ------------------------------------------------------------------ lifetime
    def __enter__(self) -> Engine:
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def start(self) -> Engine:
        """Start the pool, the LocalCluster or connect to the scheduler (idempotent)."""
        if self.kind == "local":
            if self._pool is None:
                self._pool = self._new_pool()
            return self
        if self.client is not None:
            return self
        try:
            from distributed import Client, LocalCluster
        except ImportError as exc:  # pragma: no cover - a dependency of fdikit
            raise DataError(f"Dask distributed is not installed ({exc}); "
                            "pip install 'dask[distributed]'") from None
        if self.scheduler:
            try:
                self.client = Client(self.scheduler, timeout="20s")
            except (OSError, TimeoutError) as exc:
                raise DataError(f"cannot reach the Dask scheduler at {self.scheduler!r}: {exc}") from None
        else:
            import dask

            # glibc's MALLOC_* options take effect only when set before a process starts: the
            # nannies set them before they spawn a worker (Dask's own default trims the heap at
            # 64 kB, so a worker faults its memory in again for every task)
            pre = dict(dask.config.get("distributed.nanny.pre-spawn-environ", None) or {})
            mine = {k: v for k, v in self.env.items() if k in _MALLOC_OPTIONS}
            pre.update(mine)
            saved = {k: os.environ.get(k) for k in mine}
            try:
                with dask.config.set({"distributed.nanny.pre-spawn-environ": pre,
                                      "distributed.worker.profile.enabled": self.profile}):
                    self.cluster = LocalCluster(n_workers=self.workers, threads_per_worker=1, processes=True,
                                                host="127.0.0.1", dashboard_address="127.0.0.1:0",
                                                silence_logs=40, env=self.env or None)
            finally:  # the nannies set them in this process too: not for this process's children
                for k, v in saved.items():
                    if v is None:
                        os.environ.pop(k, None)
                    else:
                        os.environ[k] = v
            self.client = Client(self.cluster)
        if self.env and self.scheduler:
            env = dict(self.env)
            self.client.run(_set_env, env)
        return self

    def close(self) -> None:
        """Shut the pool or cluster down (a remote scheduler keeps running)."""
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None
        if self.client is not None:
            self.client.close()
            self.client = None
        if self.cluster is not None:
            self.cluster.close()
            self.cluster = None

    def _new_pool(self) -> cf.ProcessPoolExecutor:
        # forkserver: workers fork from a clean server process (never from this one, whose
        # threads a fork would copy); the server imports ``preload`` once, so a pool rebuilt
        # after a worker died starts at once
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(["fdikit.evaluate.distributed", *self.preload])
        return cf.ProcessPoolExecutor(self.workers, mp_context=ctx, initializer=_set_env,
                                      initargs=(dict(self.env),))

    @property
    def n_workers(self) -> int:
        """Number of worker processes that tasks can run on now."""
        if self.kind == "dask" and self.client is not None:
            return max(1, len(self.client.scheduler_info(n_workers=-1).get("workers", {})))
        return self.workers

    def describe(self) -> dict[str, Any]:
        """What the engine is, for reports (``kind``, ``workers``, ``scheduler``)."""
        out: dict[str, Any] = {"kind": self.kind, "workers": self.n_workers}
        if self.kind == "dask" and self.client is not None:
            out["scheduler"] = self.client.scheduler.address
        return out

    # ------------------------------------------------------------------ running tasks
    def map_unordered(self, fn: Callable, items: Sequence[Any]) -> Iterator[tuple[int, Any]]:
        """Run ``fn(item)`` for every item; yield ``(index, result)`` as the tasks finish.

        ``fn`` must be importable by the workers (a module-level function). An exception raised
        by ``fn`` propagates from here (a fleet's task catches its own errors and returns them).
        """
        self.start()
        if self.kind == "dask":
            yield from self._map_dask(fn, items)
        else:
            yield from self._map_local(fn, items)

    def _map_dask(self, fn, items) -> Iterator[tuple[int, Any]]:
        from distributed import as_completed

        futures = self.client.map(fn, list(items), pure=False)
        index = {f.key: i for i, f in enumerate(futures)}
        try:
            for fut, res in as_completed(futures, with_results=True):
                yield index[fut.key], res
        finally:
            for f in futures:
                f.release()

    def _map_local(self, fn, items) -> Iterator[tuple[int, Any]]:
        todo = dict(enumerate(items))
        failures = dict.fromkeys(todo, 0)
        while todo:
            pool = self._pool
            futs = {pool.submit(fn, item): i for i, item in todo.items()}
            broken = False
            for fut in cf.as_completed(futs):
                i = futs[fut]
                try:
                    res = fut.result()
                except cf.process.BrokenProcessPool:
                    broken = True
                    continue
                del todo[i]
                yield i, res
            if broken:
                # a worker died (killed, out of memory): every unfinished task goes to a new pool
                self._pool.shutdown(wait=False, cancel_futures=True)
                self._pool = self._new_pool()
                for i in list(todo):
                    failures[i] += 1
                    if failures[i] > self.retries:
                        raise DataError(f"task {i} ({todo[i]!r}) lost its worker process "
                                        f"{failures[i]} times; giving up")


def run_chunked(fn: Callable, n_runs: int, *, chunk_size: int, args: Iterable[Any] = (),
                engine: Engine | None = None, on_chunk: Callable[[int], None] | None = None) -> list[Any]:
    """Run ``fn(start, stop, *args)`` over chunks of runs and return the chunk results in run order.

    Parameters
    ----------
    fn : callable
        ``fn(start, stop, *args)`` computes runs ``start .. stop-1``; a module-level function
        (the workers import it). Per-run seeds make its result independent of the chunking.
    n_runs : int
        Number of runs.
    chunk_size : int
        Runs per task.
    args : iterable
        Further arguments of ``fn`` (pickled once per task).
    engine : Engine, optional
        Where the chunks run; None runs them one after the other in this process.
    on_chunk : callable, optional
        Called with the number of runs of every finished chunk (a progress bar).

    Returns
    -------
    list
        ``[fn(0, c), fn(c, 2c), ...]``, in run order whatever order the tasks finished in.
    """
    bounds = chunk_bounds(int(n_runs), chunk_size)
    args = tuple(args)
    out: list[Any] = [None] * len(bounds)
    if engine is None:
        for j, (a, b) in enumerate(bounds):
            out[j] = fn(a, b, *args)
            if on_chunk is not None:
                on_chunk(b - a)
        return out
    tasks = [(fn, (a, b, *args)) for a, b in bounds]
    for j, res in engine.map_unordered(_call_task, tasks):
        out[j] = res
        if on_chunk is not None:
            on_chunk(bounds[j][1] - bounds[j][0])
    return out


def _call_task(task):
    fn, args = task
    return fn(*args)
