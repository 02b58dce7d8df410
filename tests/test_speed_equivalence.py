"""The issue-19 speed-ups of the monitor chain give the numbers of the code they replaced, bitwise.

Kept here as references: the compressed-row filter kernel (one row after the other), the scheduled
filter's run (each filter on its own, blended by numpy; the reference of the fused bank pass too),
the MHSSPT's log-likelihood kernel (every hypothesis' components evaluated), the time-vector check
and the monitor's processor pool (copied whole after every processor). Compared on random data
and on the real RAV4 minute (skipped when it is absent).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from numba import njit

from fdikit.detect.mhsspt import MHSSPT, UniformMeanGaussian, umg_component_logpdf
from fdikit.errors import DataError
from fdikit.monitor.core import Monitor
from fdikit.residuals import fdf
from fdikit.residuals.fdf import FaultDetectionFilter, FilterDesign
from fdikit.residuals.scheduled import ScheduledFilter
from fdikit.signals import Signals, check_time

from .systems.car.rav4_example import DATA, rav4_config


# ---------------------------------------------------------------------------------- references
@njit(cache=False)
def _ref_run_kernel(xi, v, ptr, col, val, out):  # pragma: no cover - compiled
    """The filter kernel before issue 19: compressed rows, one after the other."""
    nf, m = xi.shape[1], v.shape[2]
    z = np.empty(nf + m)
    tmp = np.empty(nf)
    for i in range(v.shape[0]):
        for a in range(nf):
            z[a] = xi[i, a]
        for k in range(v.shape[1]):
            for j in range(m):
                z[nf + j] = v[i, k, j]
            r = out[i, k]
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
                tmp[a] = acc
            for a in range(nf):
                z[a] = tmp[a]
        for a in range(nf):
            xi[i, a] = z[a]


def _ref_filter_run(f: FaultDetectionFilter, signals: Signals) -> np.ndarray:
    u, y = f._inputs(signals)
    f.reset(signals.runs)
    v = np.ascontiguousarray(np.concatenate([u, y], axis=2), dtype=float)
    out = np.empty((signals.runs, signals.n_samples, len(f.output_names)))
    _ref_run_kernel(f._xi, v, *f._rows, out)
    return out


def _ref_scheduled_run(g: ScheduledFilter, signals: Signals) -> Signals:
    R = [_ref_filter_run(f, signals) for f in g.filters]
    v = signals.values[:, :, signals.index([g.variable])[0]]
    if g._iv is not None:
        v = g.scale * v
    W = g._weights(v)
    out = np.zeros_like(R[0])
    for k, r in enumerate(R):
        out += W[..., k, None] * r
    return Signals(signals.t, out, g.output_names, check=False)


@njit(cache=False)
def _ref_loglik_umg(x, low, high, std, point, logw, out):  # pragma: no cover - compiled
    """The MHSSPT log likelihoods before issue 19: every component of every hypothesis."""
    T, C = x.shape[1], x.shape[2]
    H = low.shape[0]
    for r in range(x.shape[0]):
        for k in range(T):
            for j in range(H):
                acc = 0.0
                for c in range(C):
                    acc += umg_component_logpdf(x[r, k, c], low[j, c], high[j, c], std[j, c], point[j, c],
                                                logw[j, c])
                out[r, k, j] = acc


def _ref_loglik(self: MHSSPT, x):
    x = np.asarray(x, float)
    if self._umg is None or self._table is not None:
        return _NEW_LOGLIK(self, x)
    x3 = np.ascontiguousarray(x.reshape(-1, 1, x.shape[-1]) if x.ndim != 3 else x)
    out = np.empty((*x3.shape[:2], len(self.hypotheses)))
    _ref_loglik_umg(x3, *self._umg, out)
    return out.reshape((*x.shape[:-1], len(self.hypotheses)))


_NEW_LOGLIK = MHSSPT.loglik


def _ref_check_time(t, *, name="t"):
    """check_time before issue 19 (finite, then the differences)."""
    t = np.asarray(t, dtype=float)
    if t.ndim != 1:
        raise DataError(f"time vector {name!r} must be 1-D, got shape {t.shape}")
    bad = np.flatnonzero(~np.isfinite(t))
    if bad.size:
        raise DataError(f"time vector {name!r} has a non-finite value at sample {bad[0]}")
    if t.size > 1:
        dt = np.diff(t)
        bad = np.flatnonzero(dt <= 0)
        if bad.size:
            k = int(bad[0]) + 1
            raise DataError(f"time vector {name!r} is not strictly increasing at sample {k} "
                            f"(t[{k - 1}] = {t[k - 1]!r}, t[{k}] = {t[k]!r})")
    return t


def _ref_processors(self: Monitor, r: Signals) -> Signals:
    """Monitor._processors before issue 19: the pool copied whole after every processor."""
    pool = r
    for p in self.processors:
        pool = pool.concat_channels(p.run(pool))
    if not self.stat_names:
        return Signals(r.t, np.zeros((r.runs, r.n_samples, 0)), [], check=False)
    return pool.select(self.stat_names)


# ---------------------------------------------------------------------------------- random designs
def _random_design(rng, nf, m_u, m_y, q, density=0.3, dt=0.02, u_names=None, y_names=None, res=None):
    def sp(shape):
        a = rng.normal(size=shape) * (rng.uniform(size=shape) < density)
        return a
    A = sp((nf, nf))
    if nf:
        A *= 0.9 / max(1e-9, np.abs(np.linalg.eigvals(A)).max(initial=0.0) + 1e-9)
    Bu, By, C, Du, Dy = sp((nf, m_u)), sp((nf, m_y)), sp((q, nf)), sp((q, m_u)), sp((q, m_y))
    if q > 1:
        C[0] = 0.0
        Du[0] = 0.0
        Dy[0] = 0.0  # a residual row without terms
    u_names = u_names or [f"u{i}" for i in range(m_u)]
    y_names = y_names or [f"y{i}" for i in range(m_y)]
    res = res or [f"r{i}" for i in range(q)]
    return FilterDesign(A, Bu, By, C, Du, Dy, dt, u_names, y_names, res)


@pytest.mark.parametrize("seed", range(6))
def test_chunked_filter_kernel_is_bitwise_the_row_kernel(seed):
    rng = np.random.default_rng(seed)
    nf, m_u, m_y, q = (int(rng.integers(0, 30)), int(rng.integers(0, 4)), int(rng.integers(1, 5)),
                       int(rng.integers(1, 9)))
    d = _random_design(rng, nf, m_u, m_y, q, density=rng.uniform(0.05, 0.9))
    f = FaultDetectionFilter(d, x0=rng.normal(size=nf))
    runs, T = int(rng.integers(1, 4)), int(rng.integers(1, 300))
    sig = Signals(np.arange(T) * d.dt, rng.normal(size=(runs, T, m_u + m_y)) * 10.0 ** rng.integers(-3, 4),
                  [*d.u_names, *d.y_names])
    new = f.run(sig).values
    xi_new = f._xi.copy()
    ref = _ref_filter_run(f, sig)
    assert np.array_equal(new, ref, equal_nan=True)
    assert np.array_equal(xi_new, f._xi)
    # and the streaming step (the row kernel) still gives the batch numbers
    f.reset(runs)
    u, y = f._inputs(sig)
    steps = np.stack([f.step(u[:, k], y[:, k]) for k in range(T)], axis=1)
    assert np.array_equal(steps, new)


def test_chunked_filter_kernel_without_states_and_without_terms():
    rng = np.random.default_rng(7)
    for nf, m_u, m_y, q, dens in ((0, 1, 2, 3, 0.5), (5, 0, 1, 2, 0.0), (1, 1, 1, 1, 1.0)):
        d = _random_design(rng, nf, m_u, m_y, q, density=dens)
        f = FaultDetectionFilter(d)
        sig = Signals(np.arange(50) * d.dt, rng.normal(size=(2, 50, m_u + m_y)), [*d.u_names, *d.y_names])
        assert np.array_equal(f.run(sig).values, _ref_filter_run(f, sig))


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("in_y", [False, True])
def test_scheduled_filter_run_is_bitwise_the_per_filter_run(seed, in_y):
    rng = np.random.default_rng(100 + seed)
    K = int(rng.integers(1, 5))
    y_names = ["y0", "speed", "y2"] if in_y else ["y0", "y1", "y2"]
    designs = [_random_design(rng, 12, 1, 3, 4, density=0.4, u_names=["steer"], y_names=y_names)
               for _ in range(K)]
    g = ScheduledFilter(np.sort(rng.uniform(5, 30, K)) + np.arange(K), designs, variable="speed",
                        scale=0.5 if in_y else 1.0)
    T = 400
    vals = rng.normal(size=(2, T, len(g.u_names) + len(g.y_names)))
    names = [*g.u_names, *g.y_names]
    vals[:, :, names.index("speed")] = rng.uniform(0, 70, (2, T))
    sig = Signals(np.arange(T) * 0.02, vals, names)
    new = g.run(sig).values
    ref = _ref_scheduled_run(g, sig).values
    assert np.array_equal(new, ref)
    # the streaming step (numpy blend) still agrees with the batch
    g.reset(2)
    nu = len(g.u_names)
    steps = np.stack([g.step(vals[:, k, :nu], vals[:, k, nu:]) for k in range(T)], axis=1)
    assert np.array_equal(steps, new)


def _random_mhsspt(rng, H, C, shared=True, point=True):
    low = rng.uniform(-5, 5, (H, C))
    high = low + rng.uniform(0, 8, (H, C))
    std = rng.uniform(0.2, 3, (H, C))
    if shared:  # hypotheses that share the density of some channels (as calibrated ones do)
        for j in range(1, H):
            for c in range(C):
                if rng.uniform() < 0.4:
                    src = int(rng.integers(0, j))
                    low[j, c], high[j, c], std[j, c] = low[src, c], high[src, c], std[src, c]
    if point:
        high[0] = low[0]
    dens = {f"h{j}": UniformMeanGaussian(low[j], high[j], std[j]) for j in range(H)}
    return MHSSPT([f"x{c}" for c in range(C)], dens, p=1e-3, q=float(rng.choice([0.0, 1e-3])),
                  groups={"g": ["h1", f"h{H - 1}"]})


@pytest.mark.parametrize("seed", range(5))
def test_shared_component_loglik_is_bitwise_the_full_one(seed):
    rng = np.random.default_rng(200 + seed)
    H, C = int(rng.integers(2, 12)), int(rng.integers(1, 7))
    m = _random_mhsspt(rng, H, C, shared=bool(seed % 4), point=bool(seed % 2))
    R, T = int(rng.integers(1, 4)), 700
    x = rng.normal(0, 4, (R, T, C))
    x[:, ::7] *= 40.0  # far tails (the log-Phi branches)
    x[:, ::11] = m._umg[0][int(rng.integers(0, H))]  # exactly at a bound
    ref = np.empty((R, T, H))
    _ref_loglik_umg(np.ascontiguousarray(x), *m._umg, ref)
    assert np.array_equal(m.loglik(x), ref)
    # the whole test (log likelihoods, recursion, probabilities) as before
    sig = Signals(np.arange(T) * 0.02, x, m.input_names)
    new = m.run(sig).values
    MHSSPT.loglik = _ref_loglik
    try:
        old = m.run(sig).values
    finally:
        MHSSPT.loglik = _NEW_LOGLIK
    assert np.array_equal(new, old)


def test_loglik_follows_replaced_densities():
    rng = np.random.default_rng(5)
    m = _random_mhsspt(rng, 4, 3)
    m2 = _random_mhsspt(rng, 4, 3)
    m._umg = m2._umg  # the parameters changed after construction: the shared table follows
    x = rng.normal(size=(1, 200, 3))
    assert np.array_equal(m.loglik(x), m2.loglik(x))


def test_nonfinite_mhsspt_input_is_still_named():
    rng = np.random.default_rng(6)
    m = _random_mhsspt(rng, 3, 2)
    x = rng.normal(size=(1, 5000, 2))
    x[0, 3210, 1] = np.nan
    with pytest.raises(DataError, match="'x1' is not finite at sample 3210"):
        m.run(Signals(np.arange(5000) * 0.02, x, m.input_names, check=False))


@pytest.mark.parametrize("t", [
    [], [0.0], [np.nan], [np.inf], [0.0, 1.0, 2.0], [1e9 + 0.02 * k for k in range(10)],
    [0.0, np.nan, 2.0], [0.0, 1.0, np.inf], [-np.inf, 0.0, 1.0], [0.0, 1.0, 1.0, 2.0], [2.0, 1.0],
    [0.0, np.inf, np.inf], [-1e308, 1e308], [0.0, 5e-324], [5e-324, 0.0], [-0.0, 0.0], [0.0, np.nan],
])
def test_check_time_accepts_and_refuses_what_it_did(t):
    def outcome(f):
        try:
            with np.errstate(over="ignore"):
                return ("ok", f(np.asarray(t, float)).tolist())
        except DataError as e:
            return ("error", str(e))
    assert outcome(check_time) == outcome(_ref_check_time)


def test_check_time_random_records():
    rng = np.random.default_rng(9)
    for _ in range(200):
        t = np.cumsum(rng.choice([0.02, 0.0, -0.01, np.nan, np.inf], size=int(rng.integers(1, 40)),
                                 p=[0.9, 0.03, 0.03, 0.02, 0.02]))
        for f in (check_time, _ref_check_time):
            try:
                f(t)
                ok = True
            except DataError as e:
                ok = str(e)
            if f is check_time:
                a = ok
        assert a == ok


def test_join_channels_is_chained_concat():
    rng = np.random.default_rng(3)
    t = np.arange(20.0)
    parts = [Signals(t, rng.normal(size=(2, 20, n)), [f"p{i}c{j}" for j in range(n)], [f"u{i}"] * n)
             for i, n in enumerate((3, 1, 4))]
    ref = parts[0].concat_channels(parts[1]).concat_channels(parts[2])
    new = Signals.join_channels(parts)
    assert ref.equals(new) and ref.units == new.units
    with pytest.raises(DataError, match="different time grids"):
        Signals.join_channels([parts[0], Signals(t + 1, np.zeros((2, 20, 1)), ["z"])])


# ---------------------------------------------------------------------------------- monitor pool
class _PoolReader:
    """A processor outside fdikit that reads a channel it does not declare (gets the whole pool)."""

    input_names = ("a",)
    output_names = ("ab",)

    def reset(self, runs=1):
        pass

    def run(self, signals):
        return Signals(signals.t, signals["a"][..., None] + signals["b"][..., None], ["ab"], check=False)

    def step(self, r):  # pragma: no cover - the monitor asks for one; the test runs the batch
        return np.asarray(r, float)


def test_processor_pool_without_copies_gives_the_old_statistics():
    from fdikit.detect.threshold import Hold

    rng = np.random.default_rng(11)
    T = 300
    sig = Signals(np.arange(T) * 0.1, rng.normal(size=(2, T, 2)), ["a", "b"])
    from fdikit.monitor.core import Monitor as Mon

    class _Pass(fdf.ResidualGenerator):
        u_names, y_names, output_names = [], ["a", "b"], ["a", "b"]

        def reset(self, runs=1):
            pass

        def run(self, signals):
            return signals.select(["a", "b"])

    procs = [_PoolReader(), Hold(["ab"], 0.5, 3)]
    try:
        mon = Mon([_Pass()], procs)
    except Exception as exc:  # pragma: no cover - constructor variant
        raise AssertionError(f"monitor constructor: {exc}") from exc
    r = sig
    new = mon._processors(r)
    old = _ref_processors(mon, r)
    assert new.names == old.names and np.array_equal(new.values, old.values)


# ---------------------------------------------------------------------------------- the RAV4 minute
@pytest.fixture(scope="module")
def rav4_cfg(tmp_path_factory):
    if not (DATA / "drive.blf").exists():
        pytest.skip(f"RAV4 data not found at {DATA}")
    return rav4_config(tmp_path_factory.mktemp("speedcfg"))


def _run_old_and_new(cfg_path, sig):
    from fdikit.monitor.config import build_monitor, load_config

    cfg = load_config(cfg_path)
    new = build_monitor(cfg).run(sig)
    saved = (Monitor._processors, ScheduledFilter.run, MHSSPT.loglik)
    Monitor._processors, ScheduledFilter.run, MHSSPT.loglik = \
        _ref_processors, _ref_scheduled_run_any, _ref_loglik
    try:
        old = build_monitor(cfg).run(sig)
    finally:
        Monitor._processors, ScheduledFilter.run, MHSSPT.loglik = saved
    return old, new


def _ref_scheduled_run_any(self, signals):
    # Rav4LateralFilter.run calls super().run on its preprocessed channels
    return _ref_scheduled_run(self, signals)


@pytest.mark.parametrize("bias", [None, ("yaw_rate_raw", 0.05), ("wheel_fl", 1.0)])
def test_rav4_minute_monitor_is_bitwise_unchanged(rav4_cfg, bias):
    from fdikit.monitor.config import load_config, map_channels, read_log

    cfg = load_config(rav4_cfg)
    sig = map_channels(cfg, read_log(cfg, DATA / "drive.blf"))
    if bias is not None:
        v = sig.values.copy()
        v[:, 1500:, sig.index(bias[0])[0]] += bias[1]
        sig = Signals(sig.t, v, sig.names, sig.units, check=False, t0=sig.t0)
    old, new = _run_old_and_new(rav4_cfg, sig)
    assert new.residuals.names == old.residuals.names
    assert np.array_equal(new.residuals.values, old.residuals.values)
    assert new.statistics.names == old.statistics.names
    assert np.array_equal(new.statistics.values, old.statistics.values)
    assert [(e.t, e.k, e.hypothesis, e.value, e.kind) for e in new.events] == \
        [(e.t, e.k, e.hypothesis, e.value, e.kind) for e in old.events]
    assert [(e.t, e.k, e.hypothesis) for e in new.cleared] == [(e.t, e.k, e.hypothesis) for e in old.cleared]
    if bias is not None:
        assert new.events  # the fault is announced (the comparison covers events)
    assert math.isfinite(float(np.abs(new.statistics.values).max()))


def test_processor_output_colliding_with_the_pool_is_still_refused():
    from fdikit.detect.threshold import Hold

    rng = np.random.default_rng(12)
    sig = Signals(np.arange(50) * 0.1, rng.normal(size=(1, 50, 2)), ["a", "b"])

    class _Pass(fdf.ResidualGenerator):
        u_names, y_names, output_names = [], ["a", "b"], ["a", "b"]

        def reset(self, runs=1):
            pass

        def run(self, signals):
            return signals.select(["a", "b"])

    h = Hold(["a"], 0.5, 3)
    mon = Monitor([_Pass()], [h])
    h.output_names = ["b"]  # collides with a residual (the constructor refuses it; changed since)
    with pytest.raises(DataError) as new:
        mon._processors(sig)
    with pytest.raises(DataError) as old:
        _ref_processors(mon, sig)
    assert str(new.value) == str(old.value)


# ---------------------------------------------------------------------------------- the fused bank
def _bank_case(rng, K, *, same_pattern, in_y=False, nf=12):
    """K random designs reading the same channels; with ``same_pattern`` they share one nonzero
    pattern, except one input entry that half of them lack (a term the bank must skip)."""
    y_names = ["y0", "speed", "y2"] if in_y else ["y0", "y1", "y2"]
    designs = [_random_design(rng, nf, 1, 3, 4, density=0.4, u_names=["steer"], y_names=y_names)
               for _ in range(K)]
    if same_pattern:
        base = designs[0]
        for j, d in enumerate(designs):
            for name in ("A", "Bu", "By", "C", "Du", "Dy"):
                M = getattr(base, name)
                setattr(d, name, np.where(M != 0.0, rng.normal(size=M.shape), 0.0))
            d.A *= 0.9 / max(1e-9, np.abs(np.linalg.eigvals(d.A)).max(initial=0.0) + 1e-9)
            if j % 2:
                d.Bu[:] = 0.0  # the steer column: a partial column of the bank
            else:
                d.Bu[0, 0] = 1.5
    g = ScheduledFilter(np.sort(rng.uniform(5, 30, K)) + np.arange(K), designs, variable="speed",
                        scale=0.5 if in_y else 1.0)
    for f in g.filters:
        f.x0 = rng.normal(size=nf)
    return g


def _bank_signals(rng, g, T=300, runs=2):
    names = [*g.u_names, *g.y_names]
    vals = rng.normal(size=(runs, T, len(names)))
    vals[:, :, names.index("speed")] = rng.uniform(0, 70, (runs, T))
    return Signals(np.arange(T) * 0.02, vals, names)


def _new_and_ref(g, sig):
    new = g.run(sig).values
    states = [f._xi.copy() for f in g.filters]
    ref = _ref_scheduled_run(g, sig).values
    return new, states, ref, [f._xi for f in g.filters]


@pytest.mark.parametrize("seed", range(6))
def test_bank_pass_is_bitwise_the_per_filter_run(seed, monkeypatch):
    rng = np.random.default_rng(300 + seed)
    from fdikit.residuals import scheduled

    calls = []
    kernel = scheduled._run_bank_kernel

    def spy(*a):
        calls.append(kernel(*a))
        return calls[-1]

    monkeypatch.setattr(scheduled, "_run_bank_kernel", spy)
    K = 1 + seed % 4
    g = _bank_case(rng, K, same_pattern=bool(seed % 2), in_y=seed >= 3)
    sig = _bank_signals(rng, g, runs=1 + seed % 3)
    new, states, ref, ref_states = _new_and_ref(g, sig)
    assert calls == [True]  # the fused pass ran (no fallback)
    assert np.array_equal(new, ref)
    assert all(np.array_equal(a, b) for a, b in zip(states, ref_states))
    # streaming on from the batch's end state is the reference's streaming
    g.run(sig)
    nu = len(g.u_names)
    more = rng.normal(size=(sig.runs, 20, nu + len(g.y_names)))
    cont = np.stack([g.step(more[:, k, :nu], more[:, k, nu:]) for k in range(20)], axis=1)
    _ref_scheduled_run(g, sig)
    ref_cont = np.stack([g.step(more[:, k, :nu], more[:, k, nu:]) for k in range(20)], axis=1)
    assert np.array_equal(cont, ref_cont)


def test_bank_weights_at_the_edges_are_the_numpy_weights():
    rng = np.random.default_rng(310)
    for K in (1, 2, 4):
        g = _bank_case(rng, K, same_pattern=True)
        sig = _bank_signals(rng, g, T=40, runs=1)
        v = sig.values.copy()
        pts = g.speeds
        edge = [pts[0], pts[-1], np.nextafter(pts[0], -1), np.nextafter(pts[-1], 99), -0.0, 0.0, -5.0, 1e300,
                np.inf, -np.inf, np.nan, *pts, *(0.5 * (pts[:-1] + pts[1:]))]
        v[0, :len(edge), sig.index("speed")[0]] = edge
        sig = Signals(sig.t, v, sig.names, check=False)
        new, _, ref, _ = _new_and_ref(g, sig)
        assert np.array_equal(new, ref, equal_nan=True)
        assert np.isnan(new[0, 10]).all() == (K > 1)  # a NaN speed blends NaN weights (K > 1)


def test_bank_falls_back_on_a_nonfinite_value_a_filter_skips():
    from fdikit.residuals import scheduled

    rng = np.random.default_rng(320)
    g = _bank_case(rng, 4, same_pattern=True)
    bank = g._bank_structure()
    assert bank[-1].size == 1  # the steer column: two filters read it, two skip it
    sig = _bank_signals(rng, g, T=200, runs=2)
    for bad in (np.nan, np.inf):
        v = sig.values.copy()
        v[1, 120, sig.index("steer")[0]] = bad
        s = Signals(sig.t, v, sig.names, check=False)
        xi = np.zeros((2, 12, 4))
        assert not scheduled._run_bank_kernel(xi, s.values, np.asarray(s.index(["steer", "y0", "y1", "y2"])),
                                              s.index("speed")[0], False, 1.0, g.speeds, 4, *bank,
                                              np.empty((2, 200, 4)))
        with np.errstate(invalid="ignore"):
            new, states, ref, ref_states = _new_and_ref(g, s)
        assert np.array_equal(new, ref, equal_nan=True)
        assert np.isfinite(new[0]).all()  # the other run is untouched
        assert all(np.array_equal(a, b, equal_nan=True) for a, b in zip(states, ref_states))
    # a non-finite value every filter reads (no skipped term) stays in the fused pass, as NaN
    v = sig.values.copy()
    v[0, 50, sig.index("y0")[0]] = np.nan
    s = Signals(sig.t, v, sig.names, check=False)
    new, _, ref, _ = _new_and_ref(g, s)
    assert np.array_equal(new, ref, equal_nan=True)


def test_bank_not_used_where_it_does_not_apply_and_follows_new_filters():
    rng = np.random.default_rng(330)
    g5 = _bank_case(rng, 5, same_pattern=False)  # more filters than lanes
    assert g5._bank_structure() is None
    sig = _bank_signals(rng, g5)
    new, _, ref, _ = _new_and_ref(g5, sig)
    assert np.array_equal(new, ref)
    designs = [_random_design(rng, nf, 1, 3, 4, u_names=["steer"], y_names=["y0", "y1", "y2"])
               for nf in (5, 7)]
    g2 = ScheduledFilter([10.0, 20.0], designs)  # different orders
    assert g2._bank_structure() is None
    new, _, ref, _ = _new_and_ref(g2, _bank_signals(rng, g2))
    assert np.array_equal(new, ref)
    # the cached bank follows a replaced filter
    g = _bank_case(rng, 3, same_pattern=False)
    sig = _bank_signals(rng, g)
    g.run(sig)
    g.filters[1] = FaultDetectionFilter(_random_design(rng, 12, 1, 3, 4, u_names=["steer"],
                                                       y_names=["y0", "y1", "y2"]))
    new, _, ref, _ = _new_and_ref(g, sig)
    assert np.array_equal(new, ref)


def test_rav4_fleet_bank_is_bitwise_the_per_filter_run(rav4_cfg):
    from fdikit.monitor.config import build_monitor, load_config, map_channels, read_log

    cfg = load_config(rav4_cfg)
    g = build_monitor(cfg).generators[0]
    sig = map_channels(cfg, read_log(cfg, DATA / "drive.blf"))
    assert g._bank_structure() is not None
    new = g.run(sig).values
    states = [f._xi.copy() for f in g.filters]
    ref = _ref_scheduled_run(g, g.monitor_channels(sig)).values
    assert np.array_equal(new, ref)
    assert all(np.array_equal(a, f._xi) for a, f in zip(states, g.filters))
