"""Gain scheduling by residual blending: a bank of residual filters designed at several operating
points, run in parallel, whose residual is the linear interpolation, in a measured scheduling
variable, between the two filters designed at the nearest points. Every filter runs all the time,
so its state is always current when the operating point moves into its range.

The batch run of up to four plain :class:`~fdikit.residuals.FaultDetectionFilter` of one shape is
one compiled pass over the samples (:func:`_run_bank_kernel`): the filters' row sums in the lanes
of 4-double vector operations, then the weights and the blend, bitwise the numbers of each filter
run on its own and blended (and so of the streaming ``step``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.core.errors import TypingError
from numba.extending import intrinsic, models, register_model

from ..base.stage import ResidualGenerator
from ..errors import DataError
from ..signals import Signals
from .fdf import FaultDetectionFilter, FilterDesign

__all__ = ["ScheduledFilter"]


class ScheduledFilter(ResidualGenerator):
    """Residual filters designed at several operating points, blended by a scheduling variable.

    ``r = (1 - w) r_i + w r_(i+1)`` with ``p_i <= v < p_(i+1)`` and ``w = (v - p_i) / (p_(i+1) -
    p_i)``; ``v`` is clipped to ``[p_0, p_last]``.

    Parameters
    ----------
    points : sequence of float
        The operating points of the designs (e.g. speeds, m/s), increasing.
    filters : sequence of FilterDesign or ResidualGenerator
        One per point (a design is run by :class:`~fdikit.residuals.FaultDetectionFilter`), all
        reading the same channels and producing the same residuals.
    variable : str
        The scheduling channel. When it is one of the filters' measurements it is read from there
        (times ``scale``); otherwise it is an extra known input, appended to ``u_names``.
    scale : float
        Factor from the measured channel to the scheduling variable (e.g. a wheel radius over 2 for
        a sum of two wheel speeds in rad/s -> speed in m/s).

    Examples
    --------
    >>> mk = lambda g: FilterDesign(np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((0, 1)), np.zeros((1, 0)),
    ...                             np.zeros((1, 1)), np.array([[g]]), 0.1, ["u"], ["y"], ["r"])
    >>> f = ScheduledFilter([10.0, 20.0], [mk(1.0), mk(3.0)])
    >>> f.u_names, f.y_names
    (['u', 'speed'], ['y'])
    >>> f.reset(1)
    >>> float(f.step([0.0, 15.0], [1.0])[0, 0])       # halfway: (1 + 3) / 2
    2.0
    """

    _state_attrs = ("filters",)

    def __init__(self, points: Sequence[float], filters: Sequence[Any], *, variable: str = "speed",
                 scale: float = 1.0):
        self.speeds = np.asarray(points, float)
        if self.speeds.ndim != 1 or self.speeds.size < 1 or not np.all(np.isfinite(self.speeds)) \
                or np.any(np.diff(self.speeds) <= 0):
            raise DataError(f"scheduling points must be finite and increasing, got {points}")
        filters = list(filters)
        if len(filters) != self.speeds.size:
            raise DataError(f"{self.speeds.size} scheduling points but {len(filters)} filters")
        if not np.isfinite(scale) or scale == 0:
            raise DataError(f"scale must be finite and nonzero, got {scale}")
        self.designs = [f for f in filters if isinstance(f, FilterDesign)]
        if self.designs and len(self.designs) != len(filters):
            raise DataError("give either designs (FilterDesign) or residual generators, not both")
        self.filters = [FaultDetectionFilter(f) if isinstance(f, FilterDesign) else f for f in filters]
        f0 = self.filters[0]
        for f in self.filters:
            if (list(f.u_names), list(f.y_names), list(f.output_names)) != \
                    (list(f0.u_names), list(f0.y_names), list(f0.output_names)):
                raise DataError("scheduled filters must read and produce the same channels")
        self.variable, self.scale = str(variable), float(scale)
        self.y_names = list(f0.y_names)
        self._iv = self.y_names.index(self.variable) if self.variable in self.y_names else None
        self.u_names = list(f0.u_names) + ([] if self._iv is not None else [self.variable])
        self.output_names = list(f0.output_names)
        self.reset(1)

    @property
    def points(self) -> np.ndarray:
        """The operating points (the ``speeds`` attribute, named for the common case)."""
        return self.speeds

    def reset(self, runs: int = 1) -> None:
        for f in self.filters:
            f.reset(runs)

    def _weights(self, v: np.ndarray) -> np.ndarray:
        """(..., K) interpolation weights for scheduling values ``v`` (...)."""
        K = self.speeds.size
        W = np.zeros((*v.shape, K))
        if K == 1:
            W[..., 0] = 1.0
            return W
        vc = np.clip(v, self.speeds[0], self.speeds[-1])
        i = np.clip(np.searchsorted(self.speeds, vc, side="right") - 1, 0, K - 2)
        w = (vc - self.speeds[i]) / (self.speeds[i + 1] - self.speeds[i])
        np.put_along_axis(W, i[..., None], (1.0 - w)[..., None], axis=-1)
        np.put_along_axis(W, (i + 1)[..., None], w[..., None], axis=-1)
        return W

    def _blend(self, R: list[np.ndarray], v: np.ndarray) -> np.ndarray:
        W = self._weights(v)
        out = np.zeros_like(R[0])
        for k, r in enumerate(R):
            out += W[..., k, None] * r
        return out

    def _step(self, u, y):
        if self._iv is None:
            R = [f._step(u[:, :-1], y) for f in self.filters]
            return self._blend(R, u[:, -1])
        R = [f._step(u, y) for f in self.filters]
        return self._blend(R, self.scale * y[:, self._iv])

    def _plain_filters(self) -> bool:
        """True when every filter is a plain :class:`FaultDetectionFilter` (its batch run is
        :meth:`FaultDetectionFilter._run_values` of its inputs)."""
        return all(type(f).run is FaultDetectionFilter.run and type(f)._inputs is ResidualGenerator._inputs
                   for f in self.filters)

    def _variable(self, signals: Signals) -> np.ndarray:
        v = signals.values[:, :, signals.index([self.variable])[0]]
        return self.scale * v if self._iv is not None else v

    def run(self, signals: Signals) -> Signals:
        if not self._plain_filters():
            R = [f.run(signals).values for f in self.filters]
            return Signals(signals.t, self._blend(R, self._variable(signals)), self.output_names, check=False)
        # the filters read the same channels: either all of them advanced together and blended in
        # one compiled pass (_run_bank_kernel), or their inputs gathered once, each filter run on
        # its own into one array, blended in one compiled pass (the arithmetic of _blend)
        f0 = self.filters[0]
        cols = signals.index([*f0.u_names, *f0.y_names])  # (unknown channels refused first)
        if signals.n_samples > 1:
            dts = np.diff(signals.t)
            checked: set[float] = set()
            for f in self.filters:
                if f.design.dt not in checked:  # the check depends on the design's dt only
                    f._check_dt(dts, signals)
                    checked.add(f.design.dt)
        bank = self._bank_structure()
        if bank is not None:
            out = self._run_bank(bank, signals, cols)
            if out is not None:
                return Signals(signals.t, out, self.output_names, check=False)
        u, y = f0._inputs(signals)
        v = self._variable(signals)
        uy = np.ascontiguousarray(np.concatenate([u, y], axis=2), dtype=float)
        R = np.empty((len(self.filters), signals.runs, signals.n_samples, len(self.output_names)))
        for k, f in enumerate(self.filters):
            f.reset(signals.runs)
            f._run_values(uy, R[k])
        W = np.ascontiguousarray(self._weights(v))
        out = np.empty(R.shape[1:])
        _blend_kernel(R, W, out)
        return Signals(signals.t, out, self.output_names, check=False)

    def _bank_structure(self) -> tuple | None:
        """The filters' update as one :data:`LANES`-lane bank (:func:`_bank_chunks`), cached on the
        object for the filters' current row structures; None when the bank does not apply (more
        than :data:`LANES` filters, or filters of different orders or channel counts)."""
        key = tuple(getattr(f, "_rows", None) for f in self.filters)
        cached = getattr(self, "_bank", None)
        if cached is not None and len(cached[0]) == len(key) and all(a is b for a, b in zip(cached[0], key)):
            return cached[1]
        shapes = {(f._A.shape, f._C.shape, f._Bv.shape) for f in self.filters}
        bank = None
        if len(self.filters) <= LANES and len(shapes) == 1:
            bank = _bank_chunks([np.block([[f._C, f._Dv], [f._A, f._Bv]]) for f in self.filters])
        self._bank = (key, bank)
        return bank

    def _run_bank(self, bank: tuple, signals: Signals, cols: list[int]) -> np.ndarray | None:
        """Blended residuals (runs, T, q) of the record (the filters' inputs: its channels
        ``cols``), all filters from their ``x0`` in one compiled pass (:func:`_run_bank_kernel`),
        their states left at the end; None, the states untouched, when a value that one filter
        reads but another skips is not finite (see :func:`_bank_chunks`)."""
        f0 = self.filters[0]
        vals = np.ascontiguousarray(signals.values, dtype=float)
        iv = signals.index([self.variable])[0]
        xi = np.zeros((signals.runs, f0._A.shape[0], LANES))
        for k, f in enumerate(self.filters):
            xi[:, :, k] = f.x0
        out = np.empty((signals.runs, signals.n_samples, len(self.output_names)))
        if not _run_bank_kernel(xi, vals, np.asarray(cols, np.int64), iv, self._iv is not None, self.scale,
                                self.speeds, len(self.filters), *bank, out):
            return None
        for k, f in enumerate(self.filters):
            f._xi = np.ascontiguousarray(xi[:, :, k])
        return out


#: Filters advanced together by :func:`_run_bank_kernel`: the lanes of one 4-double vector.
LANES = 4
#: Rows of ``[[C, Dv], [A, Bv]]`` advanced together by :func:`_run_bank_kernel`.
BANK_ROWS = 4

# ---- 4-double vectors for the bank kernel (numba runs no SLP vectorizer: the lanes are written
# out as vector operations; each lane is the plain IEEE product and sum of its scalars)
_V4 = ir.VectorType(ir.DoubleType(), 4)


class _F64x4(types.Type):
    def __init__(self):
        super().__init__(name="F64x4")


_f64x4 = _F64x4()


@register_model(_F64x4)
class _F64x4Model(models.PrimitiveModel):
    def __init__(self, dmm, fe_type):
        super().__init__(dmm, fe_type, _V4)


def _v4_args(*pairs) -> None:
    for arr, idx in pairs:
        if not (isinstance(arr, types.Array) and arr.ndim == 1 and arr.layout == "C"
                and arr.dtype == types.float64 and isinstance(idx, types.Integer)):
            raise TypingError(f"4-double vectors need a contiguous 1-D float64 array and an integer "
                              f"index, got {arr}, {idx}")


def _v4_ptr(context, builder, arrty, arr, idx):
    """Pointer to ``arr[idx:idx + 4]`` (no bounds check: the bank's indices are built in range)."""
    data = context.make_array(arrty)(context, builder, arr).data
    return builder.bitcast(builder.gep(data, [idx]), _V4.as_pointer())


@intrinsic
def _v4_zero(typingctx):
    """The vector (0.0, 0.0, 0.0, 0.0)."""
    def codegen(context, builder, sig, args):
        return ir.Constant(_V4, [0.0] * 4)
    return _f64x4(), codegen


@intrinsic
def _v4_madd(typingctx, acc, a, ai, b, bi):
    """``acc + a[ai:ai + 4] * b[bi:bi + 4]``, lane by lane (a product, then a sum: no fused
    multiply-add)."""
    _v4_args((a, ai), (b, bi))

    def codegen(context, builder, sig, args):
        va = builder.load(_v4_ptr(context, builder, sig.args[1], args[1], args[2]), align=8)
        vb = builder.load(_v4_ptr(context, builder, sig.args[3], args[3], args[4]), align=8)
        return builder.fadd(args[0], builder.fmul(va, vb))
    return _f64x4(_f64x4, a, ai, b, bi), codegen


@intrinsic
def _v4_store(typingctx, arr, i, v):
    """``arr[i:i + 4] = v``."""
    _v4_args((arr, i))

    def codegen(context, builder, sig, args):
        builder.store(args[2], _v4_ptr(context, builder, sig.args[0], args[0], args[1]), align=8)
        return context.get_dummy_value()
    return types.none(arr, i, v), codegen


def _bank_chunks(mats: list[np.ndarray]) -> tuple[np.ndarray, ...]:
    """The update matrices ``[[C, Dv], [A, Bv]]`` of up to :data:`LANES` filters of one shape as
    one bank for :func:`_run_bank_kernel`.

    The rows of the union of the filters' nonzero patterns are grouped as in
    :func:`~fdikit.residuals.fdf._row_chunks`: rows of equal length, :data:`BANK_ROWS` at a time,
    each row's terms in column order. A term has one column for all filters and one value per
    filter (lane ``k`` for filter ``k``; zero for a filter without that entry, and in the unused
    lanes). Returns ``(length, offset, col, val, row, check)``: per chunk its number of terms
    ``n`` and its offset ``off`` (term ``e`` of row ``w`` is ``t = off + BANK_ROWS e + w``); per
    term ``LANES`` x its column (``col``, uint64) and its values ``val[LANES t:LANES (t + 1)]``;
    ``LANES`` x the chunks' rows (``BANK_ROWS`` each, uint64; the dummy row ``n_rows`` for unused
    ones); ``check`` (uint64): the columns of terms that some filter lacks. A filter skips such a
    term, the bank adds ``0.0 * z``: the same sum for a finite ``z`` (a sum from 0.0 is never
    -0.0, so a zero product leaves it unchanged), which the kernel checks."""
    M = np.asarray(mats, float)
    nz = M != 0.0
    union = nz.any(axis=0)
    partial = union & ~nz.all(axis=0)
    nr = union.shape[0]
    lens = union.sum(axis=1)
    c_len, c_off, c_col, c_val, c_row = [], [0], [], [], []
    for n in np.unique(lens):
        if n == 0:
            continue
        rows = np.flatnonzero(lens == n)
        for s in range(0, rows.size, BANK_ROWS):
            ch = rows[s:s + BANK_ROWS]
            cc = np.zeros((n, BANK_ROWS), np.uint64)
            cv = np.zeros((n, BANK_ROWS, LANES))
            rr = np.full(BANK_ROWS, nr, np.uint64)
            for w, r in enumerate(ch):
                c = np.flatnonzero(union[r])
                cc[:, w], rr[w] = c, r
                cv[:, w, :M.shape[0]] = M[:, r, c].T
            c_len.append(n)
            c_col.append(LANES * cc.ravel())
            c_val.append(cv.ravel())
            c_row.append(LANES * rr)
            c_off.append(c_off[-1] + cc.size)
    col = np.concatenate(c_col) if c_col else np.zeros(0, np.uint64)
    val = np.ascontiguousarray(np.concatenate(c_val)) if c_val else np.zeros(0)
    row = np.concatenate(c_row) if c_row else np.zeros(0, np.uint64)
    check = np.flatnonzero(partial.any(axis=0)).astype(np.uint64)
    return np.asarray(c_len, np.int64), np.asarray(c_off, np.int64), col, val, row, check


@njit(cache=True)
def _run_bank_kernel(xi, vals, cols, iv, scaled, scale, speeds, K, c_len, c_off, c_col, c_val, c_row, check,
                     out):  # pragma: no cover - compiled
    """All filters of a :func:`_bank_chunks` bank over all runs and samples, blended.

    ``xi`` (R, nf, LANES): the states (lane k: filter k), advanced in place; ``vals`` (R, T, C):
    the record, ``cols``: its channels ``[u, y]`` of the filters, ``iv``: the scheduling channel
    (times ``scale`` when ``scaled``); ``speeds``: the K points; ``out`` (R, T, q): the blended
    residuals.

    Per sample and filter, each row of ``[[C, Dv], [A, Bv]]`` is summed from 0.0 over its terms
    in column order (the filter's own sums, bitwise those of
    :func:`~fdikit.residuals.fdf._run_kernel_chunked`; the K filters in the lanes of one vector
    operation, :data:`BANK_ROWS` rows at a time); then the weights of
    :meth:`ScheduledFilter._weights` (its clip, search and arithmetic) and the blend of
    :func:`_blend_kernel` (``sum_k W_k r_k`` from 0.0 in the order of k). Returns False as soon
    as a ``check`` column is not finite in one of the K filters (``xi`` is then part-way; see
    :func:`_bank_chunks`), else True."""
    R, T = vals.shape[0], vals.shape[1]
    nf, m, q = xi.shape[1], cols.shape[0], out.shape[2]
    z = np.zeros((nf + m) * 4)        # z[4 c + k]: column c of filter k
    res = np.zeros((q + nf + 1) * 4)  # rows of no terms stay 0; the last is the unused rows' dummy
    W = np.zeros(4)
    for i in range(R):
        for a in range(nf):
            for f in range(4):
                z[4 * a + f] = xi[i, a, f]
        for k in range(T):
            for j in range(m):
                x = vals[i, k, cols[j]]
                for f in range(4):
                    z[4 * (nf + j) + f] = x
            for c in check:
                for f in range(K):
                    x = z[4 * c + f]
                    if not (x - x == 0.0):
                        return False
            for g in range(c_len.shape[0]):
                n = c_len[g]
                o = c_off[g]
                cg = c_col[o:o + 4 * n]  # a view: indices the compiler knows are not negative
                o *= 4
                a0 = _v4_zero()
                a1 = _v4_zero()
                a2 = _v4_zero()
                a3 = _v4_zero()
                for e in range(n):
                    t = 4 * e
                    b = o + 4 * t
                    a0 = _v4_madd(a0, c_val, b, z, cg[t])
                    a1 = _v4_madd(a1, c_val, b + 4, z, cg[t + 1])
                    a2 = _v4_madd(a2, c_val, b + 8, z, cg[t + 2])
                    a3 = _v4_madd(a3, c_val, b + 12, z, cg[t + 3])
                _v4_store(res, c_row[4 * g], a0)
                _v4_store(res, c_row[4 * g + 1], a1)
                _v4_store(res, c_row[4 * g + 2], a2)
                _v4_store(res, c_row[4 * g + 3], a3)
            # the weights (ScheduledFilter._weights) and the blend (_blend_kernel)
            x = vals[i, k, iv]
            if scaled:
                x = scale * x
            for f in range(4):
                W[f] = 0.0
            if K == 1:
                W[0] = 1.0
            else:
                lo = speeds[0]
                hi = speeds[K - 1]
                p = K
                if x == x:  # np.clip (NaN passes it); searchsorted(side="right") (NaN sorts last)
                    x = x if x > lo else lo
                    x = x if x < hi else hi
                    p = 0
                    while p < K and not (x < speeds[p]):
                        p += 1
                p = min(max(p - 1, 0), K - 2)
                w = (x - speeds[p]) / (speeds[p + 1] - speeds[p])
                W[p] = 1.0 - w
                W[p + 1] = w
            ok = out[i, k]
            for c in range(q):
                acc = 0.0
                for f in range(K):
                    acc += W[f] * res[4 * c + f]
                ok[c] = acc
            for a in range(4 * nf):
                z[a] = res[4 * q + a]
        for a in range(nf):
            for f in range(4):
                xi[i, a, f] = z[4 * a + f]
    return True


@njit(cache=True)
def _blend_kernel(R, W, out):  # pragma: no cover - compiled
    """out = sum_k W[..., k] R[k], summed from 0.0 in the order of k (as :meth:`ScheduledFilter._blend`):
    R (K, runs, T, q), W (runs, T, K), out (runs, T, q)."""
    K = R.shape[0]
    for i in range(R.shape[1]):
        for t in range(R.shape[2]):
            for c in range(R.shape[3]):
                acc = 0.0
                for k in range(K):
                    acc += W[i, t, k] * R[k, i, t, c]
                out[i, t, c] = acc
