"""Byte-level fuzzing shared by the binary log readers' tests (ROS bags, ULog): the mutations of a
file (:func:`mutate`) and the check that a reader either refuses the result with a clear
:class:`~fdikit.errors.DataError` or returns sound data (:func:`check_read`)."""

from __future__ import annotations

import random

import numpy as np

from fdikit.errors import DataError
from fdikit.io.formats import MultiRateSignals

#: The mutations of :func:`mutate`.
BIN_OPS = ("truncate", "corrupt", "zero-block", "append-garbage")


def mutate(data: bytes, op: str, seed: int) -> bytes:
    """``data`` cut short at a random place (``truncate``), with 1, 3 or 20 random bytes
    (``corrupt``), with a block of 8 to 511 bytes zeroed (``zero-block``) or with 1 to 199 random
    bytes appended (``append-garbage``), drawn from ``random.Random(seed)``."""
    r = random.Random(seed)
    data = bytearray(data)
    if op == "truncate":
        data = data[: r.randrange(1, len(data))]
    elif op == "corrupt":
        for _ in range(r.choice([1, 3, 20])):
            data[r.randrange(len(data))] = r.randrange(256)
    elif op == "zero-block":
        a = r.randrange(len(data))
        n = min(len(data) - a, r.randrange(8, 512))
        data[a: a + n] = bytes(n)
    elif op == "append-garbage":
        data += bytes(r.randrange(256) for _ in range(r.randrange(1, 200)))
    else:
        raise ValueError(f"unknown mutation {op!r} (one of {', '.join(BIN_OPS)})")
    return bytes(data)


def check_read(fn, says: str):
    """Call the reader ``fn``: a :class:`DataError` whose message contains ``says`` (returns the
    message) or sound data, every sample's validity its finiteness (returns the signals)."""
    try:
        out = fn()
    except DataError as exc:
        assert says in str(exc), str(exc)
        return str(exc)
    assert isinstance(out, MultiRateSignals)
    np.testing.assert_array_equal(out.valid, np.isfinite(out.values))
    return out
