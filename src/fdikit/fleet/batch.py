"""Batching a fleet's logs into tasks: guided scheduling, large tasks while much remains and one log
each at the end, so that the workers finish together (:func:`batch_size`, :func:`batches`)."""

from __future__ import annotations

__all__ = ["MAX_BATCH", "batch_size", "batches"]

#: The most logs in one fleet task: a task's dispatch and its result's trip cost about a log's
#: commit on a LocalCluster, so 16 logs spread it to a few percent of a log each.
MAX_BATCH = 16


def batch_size(n_logs: int, n_workers: int) -> int:
    """Logs in the next fleet task when ``n_logs`` remain: a quarter of each worker's share, 1 to
    :data:`MAX_BATCH` (guided scheduling: large tasks while much remains, smaller ones towards the
    end, so that the workers finish together, the last tasks one log each); one worker has
    nobody to wait for and takes :data:`MAX_BATCH` throughout.

    Parameters
    ----------
    n_logs : int
        Logs that remain to be given out.
    n_workers : int
        Workers of the engine.

    Returns
    -------
    int

    Examples
    --------
    >>> batch_size(200, 2), batch_size(200, 1), batch_size(20, 2), batch_size(3, 2), batch_size(5, 1)
    (16, 16, 3, 1, 5)
    """
    if n_workers <= 1:
        return max(1, min(MAX_BATCH, n_logs))
    return max(1, min(MAX_BATCH, -(-n_logs // (4 * n_workers))))


def batches(todo: list, n_workers: int) -> list[list]:
    """The logs ``todo`` cut into fleet tasks of :func:`batch_size` logs each, in order.

    Parameters
    ----------
    todo : list
        The logs (tasks) still to do.
    n_workers : int
        Workers of the engine.

    Returns
    -------
    list of list

    Examples
    --------
    >>> [len(b) for b in batches(list(range(40)), 2)]
    [5, 5, 4, 4, 3, 3, 2, 2, 2, 2, 1, 1, 1, 1, 1, 1, 1, 1]
    """
    out, i = [], 0
    while i < len(todo):
        k = batch_size(len(todo) - i, n_workers)
        out.append(todo[i:i + k])
        i += k
    return out
