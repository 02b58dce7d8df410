"""One test of a fault direction from per-channel one-sided statistics: the compiled combination
over a signature (and its rivals) that the drift and gain detectors share.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(inline="always")
def _min_nan(a, b):  # pragma: no cover
    """``np.minimum(a, b)``: a NaN operand is the result."""
    return a if (a <= b or a != a) else b


@njit(inline="always")
def _max_nan(a, b):  # pragma: no cover
    """``np.maximum(a, b)``: a NaN operand is the result."""
    return a if (a >= b or a != a) else b


@njit(cache=True)
def _combine_kernel(gp, gm, sigma2, sigs, thr, sides, out):  # pragma: no cover
    """Combined one-sided statistics: gp, gm (R, T, C) unscaled -> out (R, T, 1 or 4).

    With ``q = g / sigma2`` per channel, the statistic of a signature in its direction is the
    least ``q+`` (``q-``) over its channels with a positive (negative) entry, and in the opposite
    direction the same with the signs swapped; ``up`` and ``down`` are those of ``sigs[0]``, set
    to 0 wherever a rival ``sigs[i]``, ``i >= 1``, has ``max(its up, its down) >= them`` (in turn).
    ``out[..., 0]`` is ``max(up / thr, down / thr)`` with ``sides`` (and then ``out[..., 2:4]``
    the two), else ``max(up, down) / thr``. Sample by sample, the numbers of the numpy
    expressions it replaces (:meth:`GainDetector._compute`, :meth:`DriftDetector._compute`):
    the same divisions, and minima and maxima that pass a NaN on as numpy's do.
    """
    R, T, C = gp.shape
    K = sigs.shape[0]
    qp = np.empty(C)
    qm = np.empty(C)
    for r in range(R):
        for k in range(T):
            for c in range(C):
                qp[c] = gp[r, k, c] / sigma2[c]
                qm[c] = gm[r, k, c] / sigma2[c]
            up = 0.0
            down = 0.0
            for i in range(K):
                u = 0.0
                d = 0.0
                seen = False
                for c in range(C):
                    sg = sigs[i, c]
                    if sg == 0.0:
                        continue
                    p = qp[c]
                    m = qm[c]
                    if not sg > 0.0:
                        p, m = m, p
                    if seen:
                        u = _min_nan(u, p)
                        d = _min_nan(d, m)
                    else:
                        u = p
                        d = m
                        seen = True
                if i == 0:
                    up = u
                    down = d
                else:  # another fault explains the residuals as well: not this one
                    best = _max_nan(u, d)
                    if best >= up:
                        up = 0.0
                    if best >= down:
                        down = 0.0
            if sides:
                up = up / thr
                down = down / thr
                out[r, k, 0] = _max_nan(up, down)
                out[r, k, 2] = up
                out[r, k, 3] = down
            else:
                out[r, k, 0] = _max_nan(up, down) / thr
