"""The random numbers inside the numba kernel: xoshiro256** and Marsaglia polar normals."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

_U64 = np.uint64


@njit(cache=True, inline="always")
def _rotl(x, k):
    return (x << _U64(k)) | (x >> _U64(64 - k))


@njit(cache=True)
def _next_u64(s):
    """xoshiro256** (Blackman & Vigna, 2018) on the 4-word state ``s`` (updated in place)."""
    s0, s1, s2, s3 = s[0], s[1], s[2], s[3]
    result = _rotl(s1 * _U64(5), 7) * _U64(9)
    t = s1 << _U64(17)
    s2 ^= s0
    s3 ^= s1
    s1 ^= s2
    s0 ^= s3
    s2 ^= t
    s3 = _rotl(s3, 45)
    s[0], s[1], s[2], s[3] = s0, s1, s2, s3
    return result


@njit(cache=True)
def _uniform(s):
    """Uniform on [0, 1) with 53 random bits."""
    return float(_next_u64(s) >> _U64(11)) * (1.0 / 9007199254740992.0)


@njit(cache=True)
def _normal_pair(s):
    """Two independent standard normals (Marsaglia polar method)."""
    while True:
        a = 2.0 * _uniform(s) - 1.0
        b = 2.0 * _uniform(s) - 1.0
        r = a * a + b * b
        if 0.0 < r < 1.0:
            f = math.sqrt(-2.0 * math.log(r) / r)
            return a * f, b * f
