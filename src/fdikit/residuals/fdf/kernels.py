"""Compiled kernels of the filter runtime: the compressed rows of ``[[C, Dv], [A, Bv]]`` and the
per-sample and whole-record updates over them (bitwise equal to one another)."""

from __future__ import annotations

import numpy as np
from numba import njit


def _sparse_rows(M: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Compressed rows of ``M`` (its nonzero entries in column order): ``(ptr, col, val)``.

    The filters of a bank are stacked block-diagonally (:func:`stack_designs`), so most of
    ``[[C, Dv], [A, Bv]]`` is structurally zero; the runtime multiplies the nonzeros only, in the
    same column order as the dense product (the skipped terms are exact zeros).
    """
    M = np.asarray(M, float)
    nz = M != 0.0
    ptr = np.zeros(M.shape[0] + 1, np.int64)
    ptr[1:] = np.cumsum(nz.sum(axis=1))
    rows, cols = np.nonzero(nz)
    return ptr, np.ascontiguousarray(cols, dtype=np.int64), np.ascontiguousarray(M[rows, cols])


@njit(cache=True)
def _advance_row(z, nf, ptr, col, val, r, q):  # pragma: no cover - compiled
    """One sample of one run, in place on ``z = [xi, v]`` (nf + m,):
    r = C xi + Dv v; xi <- A xi + Bv v, with ``[[C, Dv], [A, Bv]]`` in compressed rows (q + nf rows);
    the new state is formed in ``r``'s tail scratch ``q[...]`` before it overwrites ``xi``."""
    nr = r.shape[0]
    for a in range(nr):
        acc = 0.0
        for e in range(ptr[a], ptr[a + 1]):
            acc += val[e] * z[col[e]]
        r[a] = acc
    for a in range(nf):
        acc = 0.0
        for e in range(ptr[nr + a], ptr[nr + a + 1]):
            acc += val[e] * z[col[e]]
        q[a] = acc
    for a in range(nf):
        z[a] = q[a]


@njit(cache=True)
def _step_kernel(xi, v, ptr, col, val, r):  # pragma: no cover - compiled
    """All runs, one sample: xi (R, nf) in place, v (R, m), r (R, q)."""
    nf, m = xi.shape[1], v.shape[1]
    z = np.empty(nf + m)
    tmp = np.empty(nf)
    for i in range(xi.shape[0]):
        for a in range(nf):
            z[a] = xi[i, a]
        for j in range(m):
            z[nf + j] = v[i, j]
        _advance_row(z, nf, ptr, col, val, r[i], tmp)
        for a in range(nf):
            xi[i, a] = z[a]


@njit(cache=True)
def _run_kernel(xi, v, ptr, col, val, out):  # pragma: no cover - compiled
    """All runs, all samples: v (R, T, m), out (R, T, q); the same row arithmetic as the step."""
    nf, m = xi.shape[1], v.shape[2]
    z = np.empty(nf + m)
    tmp = np.empty(nf)
    for i in range(v.shape[0]):
        for a in range(nf):
            z[a] = xi[i, a]
        for k in range(v.shape[1]):
            for j in range(m):
                z[nf + j] = v[i, k, j]
            _advance_row(z, nf, ptr, col, val, out[i, k], tmp)
        for a in range(nf):
            xi[i, a] = z[a]


#: Rows of ``[[C, Dv], [A, Bv]]`` advanced together by :func:`_run_kernel_chunked`.
CHUNK = 4


def _row_chunks(ptr: np.ndarray, col: np.ndarray, val: np.ndarray) -> tuple[np.ndarray, ...]:
    """The compressed rows regrouped for :func:`_run_kernel_chunked`: rows of equal length in
    chunks of :data:`CHUNK`, their terms interleaved (term ``e`` of lane ``w`` at ``CHUNK e + w``,
    each row's terms in their own order); a chunk's unused lanes multiply zeros into the dummy
    row ``n_rows``. Returns ``(length, offset, col, val, row)`` per chunk (``col`` unsigned; rows
    of no terms are in no chunk: they stay 0)."""
    nr = ptr.size - 1
    lens = np.diff(ptr)
    c_len, c_off, c_col, c_val, c_row = [], [0], [], [], []
    for n in np.unique(lens):
        if n == 0:
            continue
        rows = np.flatnonzero(lens == n)
        for s in range(0, rows.size, CHUNK):
            ch = rows[s:s + CHUNK]
            cc = np.zeros((n, CHUNK), np.int64)
            cv = np.zeros((n, CHUNK))
            rr = np.full(CHUNK, nr, np.int64)
            for w, r in enumerate(ch):
                cc[:, w], cv[:, w], rr[w] = col[ptr[r]:ptr[r + 1]], val[ptr[r]:ptr[r + 1]], r
            c_len.append(n)
            c_col.append(cc.ravel())
            c_val.append(cv.ravel())
            c_row.append(rr)
            c_off.append(c_off[-1] + cc.size)

    def cat(a: list, dt: type) -> np.ndarray:
        return np.ascontiguousarray(np.concatenate(a), dtype=dt) if a else np.zeros(0, dt)

    return (np.asarray(c_len, np.int64), np.asarray(c_off, np.int64), cat(c_col, np.uint64),
            cat(c_val, np.float64), cat(c_row, np.int64))


@njit(cache=True)
def _run_kernel_chunked(xi, v, c_len, c_off, c_col, c_val, c_row, out):  # pragma: no cover - compiled
    """As :func:`_run_kernel` (bitwise: every row sums the same terms in the same order from 0.0),
    with :data:`CHUNK` rows of equal length advanced together (independent sums the processor
    overlaps, and no loop exit per row): v (R, T, m), out (R, T, q), xi (R, nf) in place."""
    nf, m = xi.shape[1], v.shape[2]
    q = out.shape[2]
    z = np.empty(nf + m)
    res = np.zeros(q + nf + 1)  # rows of no terms stay 0; the last is the unused lanes' dummy
    for i in range(v.shape[0]):
        for a in range(nf):
            z[a] = xi[i, a]
        for k in range(v.shape[1]):
            for j in range(m):
                z[nf + j] = v[i, k, j]
            for g in range(c_len.shape[0]):
                # views and unsigned columns: indices the compiler knows are not negative (no
                # wrap-around test per term)
                n = c_len[g]
                cg = c_col[c_off[g]:c_off[g] + 4 * n]
                vg = c_val[c_off[g]:c_off[g] + 4 * n]
                a0 = 0.0
                a1 = 0.0
                a2 = 0.0
                a3 = 0.0
                for e in range(n):
                    a0 += vg[4 * e] * z[cg[4 * e]]
                    a1 += vg[4 * e + 1] * z[cg[4 * e + 1]]
                    a2 += vg[4 * e + 2] * z[cg[4 * e + 2]]
                    a3 += vg[4 * e + 3] * z[cg[4 * e + 3]]
                w = 4 * g
                res[c_row[w]] = a0
                res[c_row[w + 1]] = a1
                res[c_row[w + 2]] = a2
                res[c_row[w + 3]] = a3
            o = out[i, k]
            for a in range(q):
                o[a] = res[a]
            for a in range(nf):
                z[a] = res[q + a]
        for a in range(nf):
            xi[i, a] = z[a]
