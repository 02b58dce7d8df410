"""The blocked window kernels of the drift and gain detectors against the per-sample kernels they
replace (issue 19).

``_ramp_reference`` and ``_gain_reference`` below are the kernels of ``fdikit.detect.sensor`` as
they were before issue 19: per sample, the sums over the last ``L = 1 .. n`` samples accumulated
backwards from the newest one, the GLR maximised over ``L``. The blocked kernels evaluate a block
of samples at once (candidates in the outer loop, two at a time, samples in the inner, vectorised
one) with each sample's sums taken in the same order, so the outputs *and the ring-buffer states*
must be bitwise equal -- on random data in pieces of random length (one sample at a time as
streaming does, pieces shorter and longer than a block), with resets between pieces (what the
monitor does after a held gap), for every ``min_length`` of small windows (where candidates are
taken alone or in pairs), and through a monitor over a record with NaN-held gaps.

The ramp kernel's blocked loops approximate the step GLR and compute it exactly where the
approximation does not settle the comparison (``sensor._step_known``): that rule is checked
against the exact comparison on terms at and around ties, tiny and subnormal ones.

The glue around the kernels is checked the same way: ``_gain_run`` (results of a previous call
reused for residuals whose inputs are bitwise the same) against the kernel itself, and
``_combine_kernel`` against the numpy expressions it replaces (``_combined_reference``).
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from numba import njit

from fdikit import Signals
from fdikit.detect import Hold, design_drift, design_gain, sensor
from fdikit.faults import Bias
from fdikit.monitor import Decision, Monitor
from fdikit.residuals import ObserverResidual, design_observer_residual
from fdikit.systems import two_mass


# ---------------------------------------------------------------------------------- references
@njit(cache=False)
def _ramp_reference(x, mu0, W, Lmin, vs_step, out_p, out_m, buf, pos, cnt):  # pragma: no cover
    R, T, C = x.shape
    for r in range(R):
        for c in range(C):
            b = buf[r, c]
            for k in range(T):
                p = pos[r, c]
                b[p] = x[r, k, c] - mu0[c]
                p = (p + 1) % W
                pos[r, c] = p
                if cnt[r, c] < W:
                    cnt[r, c] += 1
                n = cnt[r, c]
                s0 = 0.0
                s1 = 0.0
                gp = 0.0
                gm = 0.0
                gs = 0.0
                i = p
                for L in range(1, n + 1):
                    i -= 1
                    if i < 0:
                        i += W
                    s0 += b[i]
                    s1 += s0
                    vs = s0 * s0 / L
                    if vs > gs:
                        gs = vs
                    if L >= Lmin:
                        den = L * (L + 1.0) * (2.0 * L + 1.0) / 6.0
                        v = s1 * s1 / den
                        if s1 > 0.0:
                            if v > gp:
                                gp = v
                        elif v > gm:
                            gm = v
                if vs_step:
                    if gp <= gs:
                        gp = 0.0
                    if gm <= gs:
                        gm = 0.0
                out_p[r, k, c] = gp
                out_m[r, k, c] = gm


@njit(cache=False)
def _gain_reference(x, s, mu0, W, Lmin, mg, gsc, out_p, out_m, est, bx, bs, pos, cnt):  # pragma: no cover
    R, T, C = x.shape
    for r in range(R):
        for k in range(T):
            p = pos[r]
            bs[r, p] = s[r, k]
            for c in range(C):
                bx[r, c, p] = x[r, k, c] - mu0[c]
            p = (p + 1) % W
            pos[r] = p
            if cnt[r] < W:
                cnt[r] += 1
            n = cnt[r]
            for c in range(C):
                a = 0.0
                bb = 0.0
                g = 0.0
                gm = 0.0
                best = -1.0
                th = 0.0
                i = p
                for L in range(1, n + 1):
                    i -= 1
                    if i < 0:
                        i += W
                    a += bx[r, c, i] * bs[r, i]
                    bb += bs[r, i] * bs[r, i]
                    if L >= Lmin and bb > 0.0:
                        v = a * a / bb
                        if v > best:
                            best = v
                            th = a / bb
                        if mg > 0.0 and abs(a) < mg * gsc[c] * bb:
                            continue
                        if a > 0.0:
                            if v > g:
                                g = v
                        elif v > gm:
                            gm = v
                out_p[r, k, c] = g
                out_m[r, k, c] = gm
                est[r, k, c] = th


# ---------------------------------------------------------------------------------- random data
def _residuals(rng, R, T, C):
    """Noise plus ramps, steps and flat stretches at random places and scales (large offsets too)."""
    scale = 10.0 ** rng.uniform(-4, 3, size=C)
    x = rng.standard_normal((R, T, C)) * scale
    for _ in range(3):
        a = int(rng.integers(0, T))
        b = int(rng.integers(a, T + 1))
        ramp = rng.uniform(0, 5) + rng.uniform(0, 0.2) * np.arange(b - a)[None, :, None]
        x[:, a:b] += rng.choice([-1, 1]) * scale * ramp
    a = int(rng.integers(0, T))
    x[:, a:a + int(rng.integers(1, 40))] = x[:, a:a + 1]  # held (flat) samples
    return np.ascontiguousarray(x)


def _pieces(rng, T):
    """Random cut points: single samples, short and long pieces; and where a reset precedes them."""
    cuts, k = [0], 0
    while k < T:
        B = sensor._BLOCK
        k = min(T, k + int(rng.choice([1, 1, 3, 15, 16, 17, 255, 256, 257, 700, B - 1, B, B + 1])))
        cuts.append(k)
    resets = rng.random(len(cuts) - 1) < 0.25
    return list(itertools.pairwise(cuts)), resets


def _run_ramp(kernel, x, mu0, W, Lmin, vs, pieces, resets):
    R, T, C = x.shape
    out_p, out_m = np.full((R, T, C), -7.0), np.full((R, T, C), -7.0)
    states = []
    buf, pos, cnt = np.zeros((R, C, W)), np.zeros((R, C), np.int64), np.zeros((R, C), np.int64)
    for (a, b), reset in zip(pieces, resets):
        if reset:
            buf, pos, cnt = np.zeros((R, C, W)), np.zeros((R, C), np.int64), np.zeros((R, C), np.int64)
        p, m = np.empty((R, b - a, C)), np.empty((R, b - a, C))
        kernel(np.ascontiguousarray(x[:, a:b]), mu0, W, Lmin, vs, p, m, buf, pos, cnt)
        out_p[:, a:b], out_m[:, a:b] = p, m
        states.append((buf.copy(), pos.copy(), cnt.copy()))
    return out_p, out_m, states


@pytest.mark.parametrize("seed", range(10))
def test_ramp_kernel_is_bitwise_the_per_sample_kernel(seed):
    rng = np.random.default_rng(seed)
    R, C = int(rng.integers(1, 3)), int(rng.integers(1, 4))
    W = int(rng.choice([1, 2, 5, 16, 100, 300, 1000]))
    Lmin = int(rng.integers(1, W + 1))
    vs = bool(rng.random() < 0.5)
    T = int(rng.integers(1, 2500))
    x = _residuals(rng, R, T, C)
    mu0 = rng.standard_normal(C) * 0.1
    pieces, resets = _pieces(rng, T)
    fast = _run_ramp(sensor._ramp_kernel, x, mu0, W, Lmin, vs, pieces, resets)
    ref = _run_ramp(_ramp_reference, x, mu0, W, Lmin, vs, pieces, resets)
    assert np.array_equal(fast[0], ref[0]) and np.array_equal(fast[1], ref[1])
    assert (fast[0] > 0).any() or (fast[1] > 0).any() or T < Lmin  # not a comparison of zeros
    for (b1, p1, c1), (b2, p2, c2) in zip(fast[2], ref[2]):
        assert np.array_equal(b1, b2) and np.array_equal(p1, p2) and np.array_equal(c1, c2)


def _run_gain(kernel, x, s, mu0, W, Lmin, mg, gsc, pieces, resets):
    R, T, C = x.shape
    outs = [np.full((R, T, C), -7.0) for _ in range(3)]
    states = []

    def fresh():
        return np.zeros((R, C, W)), np.zeros((R, W)), np.zeros(R, np.int64), np.zeros(R, np.int64)

    bx, bs, pos, cnt = fresh()
    for (a, b), reset in zip(pieces, resets):
        if reset:
            bx, bs, pos, cnt = fresh()
        o = [np.empty((R, b - a, C)) for _ in range(3)]
        kernel(np.ascontiguousarray(x[:, a:b]), np.ascontiguousarray(s[:, a:b]), mu0, W, Lmin, mg, gsc,
               *o, bx, bs, pos, cnt)
        for full, part in zip(outs, o):
            full[:, a:b] = part
        states.append((bx.copy(), bs.copy(), pos.copy(), cnt.copy()))
    return outs, states


@pytest.mark.parametrize("seed", range(10))
def test_gain_kernel_is_bitwise_the_per_sample_kernel(seed):
    rng = np.random.default_rng(100 + seed)
    R, C = int(rng.integers(1, 3)), int(rng.integers(1, 4))
    W = int(rng.choice([1, 2, 5, 16, 100, 250, 600]))
    Lmin = int(rng.integers(1, W + 1))
    T = int(rng.integers(1, 2000))
    s = 20.0 + np.cumsum(rng.standard_normal((R, T)), axis=1) * 0.2
    a = int(rng.integers(0, T))
    s[:, a:a + int(rng.integers(1, 30))] = 0.0  # a signal at zero: sum s^2 = 0 for short windows
    theta = np.where(rng.random((R, T, C)) < 0.5, 0.0, rng.uniform(-0.05, 0.05, (1, 1, C)))
    x = np.ascontiguousarray(rng.standard_normal((R, T, C)) * 0.05 + theta * s[:, :, None])
    mu0 = rng.standard_normal(C) * 0.01
    mg = float(rng.choice([0.0, 0.003, 0.03]))
    gsc = rng.uniform(0.5, 2.0, C)
    pieces, resets = _pieces(rng, T)
    fast = _run_gain(sensor._gain_kernel, x, s, mu0, W, Lmin, mg, gsc, pieces, resets)
    ref = _run_gain(_gain_reference, x, s, mu0, W, Lmin, mg, gsc, pieces, resets)
    for u, v in zip(fast[0], ref[0]):
        assert np.array_equal(u, v)
    assert (fast[0][2] != 0).any() or T < Lmin
    for st1, st2 in zip(fast[1], ref[1]):
        assert all(np.array_equal(u, v) for u, v in zip(st1, st2))


# ---------------------------------------------------------------------------------- in a monitor
def _monitor():
    """Drift and gain detectors calibrated on a nominal record of the two-mass example, in a monitor."""
    obs = design_observer_residual(two_mass.model(), dt=two_mass.DT, Q=np.eye(4) * 1e-8,
                                   R=np.eye(2) * two_mass.NOISE_STD**2)
    gen = ObserverResidual(obs)
    nom = gen.run(two_mass.record((), 2, 11, duration=12.0))
    drift = design_drift(nom, gen.output_names, 300, signature=[1, 1], name="both", min_length=20,
                         vs_step=True, skip=30)
    gain = design_gain(nom, ["r:pos2"], "r:pos1", 120, min_length=10, min_gain=0.01, skip=30)
    drift_alone = design_drift(nom, ["r:pos2"], 150)
    hold = Hold([*drift.output_names, "r:pos2:gain", *drift_alone.output_names], 1.0, Z=3, absolute=False)
    return Monitor([gen], [drift, gain, drift_alone, hold], Decision(hold.output_names), on_invalid="hold",
                   warmup=0.5)


def test_monitor_with_held_gaps_gives_the_per_sample_kernels_numbers(monkeypatch):
    rec = two_mass.record([Bias("sensor:pos2", 0.02, start=6.0)], 2, 5, duration=12.0)
    v = rec.values.copy()
    v[0, 300:340] = np.nan  # a held NaN block in run 0 (the detectors restart after it)
    v[1, 700:705, 1] = np.nan
    rec = Signals(rec.t, v, rec.names, check=False)
    fast = _monitor().run(rec)
    monkeypatch.setattr(sensor.drift, "_ramp_kernel", _ramp_reference)
    monkeypatch.setattr(sensor.gain, "_gain_kernel", _gain_reference)
    monkeypatch.setattr(sensor.gain, "_GAIN_LAST", [None])  # nothing of the fast run reused
    ref = _monitor().run(rec)
    assert np.array_equal(fast.statistics.values, ref.statistics.values)
    assert np.nanmax(fast.statistics.values) > 1.0  # alarms: not a comparison of zeros
    key = lambda e: (e.run, e.k, e.hypothesis, e.value, e.kind)  # noqa: E731
    assert [key(e) for e in fast.events] == [key(e) for e in ref.events] and fast.events


@pytest.mark.parametrize("W", [1, 2, 3, 4, 7, 8])
def test_kernels_bitwise_for_every_min_length_of_small_windows(W):
    """Candidates are taken in pairs where both are on the same side of ``Lmin``, alone at ``Lmin``
    (by parity), at the window's end and for the sample whose window is just one candidate long."""
    rng = np.random.default_rng(W)
    T, R, C = 60, 2, 2
    x = _residuals(rng, R, T, C)
    s = 20.0 + np.cumsum(rng.standard_normal((R, T)), axis=1) * 0.2
    s[:, 5:9] = 0.0
    mu0 = rng.standard_normal(C) * 0.1
    for Lmin in range(1, W + 1):
        for cuts in ([(0, T)], [(0, 1), (1, 2), (2, 19), (19, 20), (20, T)], [(0, 3), (3, 40), (40, T)]):
            resets = [False, *(rng.random(len(cuts) - 1) < 0.3)]
            for vs in (False, True):
                fast = _run_ramp(sensor._ramp_kernel, x, mu0, W, Lmin, vs, cuts, resets)
                ref = _run_ramp(_ramp_reference, x, mu0, W, Lmin, vs, cuts, resets)
                assert np.array_equal(fast[0], ref[0]) and np.array_equal(fast[1], ref[1])
            for mg in (0.0, 0.02):
                fast = _run_gain(sensor._gain_kernel, x, s, mu0, W, Lmin, mg, np.ones(C), cuts, resets)
                ref = _run_gain(_gain_reference, x, s, mu0, W, Lmin, mg, np.ones(C), cuts, resets)
                assert all(np.array_equal(u, v) for u, v in zip(fast[0], ref[0]))
                for st1, st2 in zip(fast[1], ref[1]):
                    assert all(np.array_equal(u, v) for u, v in zip(st1, st2))


# ---------------------------------------------------------------------------------- gain memo
def _gain_data(rng, R=2, T=500, C=3):
    s = 20.0 + np.cumsum(rng.standard_normal((R, T)), axis=1) * 0.2
    theta = np.where(rng.random((R, T, C)) < 0.5, 0.0, rng.uniform(-0.05, 0.05, (1, 1, C)))
    x = np.ascontiguousarray(rng.standard_normal((R, T, C)) * 0.05 + theta * s[:, :, None])
    return x, s


def test_gain_run_reuses_exactly_the_residuals_with_the_same_inputs(monkeypatch):
    """``_gain_run`` gives the kernel's outputs and states whatever the previous call was, and runs
    the kernel only on the residuals whose inputs (column, mu0, gain_scale, ring buffer, and the
    shared signal and state) are not bitwise those of the previous call."""
    rng = np.random.default_rng(7)
    x, s = _gain_data(rng)
    R, _, C = x.shape
    W, Lmin, mg = 120, 10, 0.01
    mu0 = rng.standard_normal(C) * 0.01
    gsc_front, gsc_rear = np.ones(C), np.array([1.0, 1.0, 1.3])
    kernel = sensor._gain_kernel
    ran = []

    def spy(xs, *args):
        ran.append(xs.shape[2])
        return kernel(xs, *args)

    monkeypatch.setattr(sensor.gain, "_gain_kernel", spy)
    monkeypatch.setattr(sensor.gain, "_GAIN_LAST", [None])

    def fresh():
        return [np.zeros((R, C, W)), np.zeros((R, W)), np.zeros(R, np.int64), np.zeros(R, np.int64)]

    def direct(x, s, mu0, gsc, state):
        st = [a.copy() for a in state]
        o = [np.empty(x.shape) for _ in range(3)]
        kernel(x, s, mu0, W, Lmin, mg, gsc, *o, *st)
        return np.stack(o), st

    def check(x, s, mu0, gsc, state, expect_ran):
        del ran[:]
        st = [a.copy() for a in state]
        out = sensor._gain_run(x, s, mu0, W, Lmin, mg, gsc, *st)
        ref, ref_st = direct(x, s, mu0, gsc, state)
        assert np.array_equal(out.view(np.int64), ref.view(np.int64))
        assert all(np.array_equal(u, v) for u, v in zip(st, ref_st))
        assert not out.flags.writeable  # what a later call copies from cannot be changed
        assert ran == expect_ran
        return st

    check(x, s, mu0, gsc_front, fresh(), [3])
    check(x, s, mu0, gsc_rear, fresh(), [1])  # the front and rear checks: one residual differs
    check(x, s, mu0, gsc_rear, fresh(), [])  # all reused, the shared state too
    x2 = x.copy()
    x2[1, 250, 0] = np.nextafter(x2[1, 250, 0], np.inf)  # one bit of one residual
    check(x2, s, mu0, gsc_rear, fresh(), [1])
    mu2 = mu0.copy()
    mu2[2] = np.nextafter(mu2[2], 1.0)
    check(x2, s, mu2, gsc_rear, fresh(), [1])
    s2 = s.copy()
    s2[0, 3] = np.nextafter(s2[0, 3], 0.0)  # the shared signal: everything again
    check(x2, s2, mu2, gsc_rear, fresh(), [3])
    # a state carried over from an earlier piece (streaming in pieces): part of the inputs
    st = check(x[:, :100], s[:, :100], mu0, gsc_front, fresh(), [3])
    after = check(np.ascontiguousarray(x[:, 100:]), np.ascontiguousarray(s[:, 100:]), mu0, gsc_front, st, [3])
    check(np.ascontiguousarray(x[:, 100:]), np.ascontiguousarray(s[:, 100:]), mu0, gsc_front, st, [])
    st_other = [a.copy() for a in st]
    st_other[0][1, 2, 5] += 1e-3  # another ring buffer of residual 2
    check(np.ascontiguousarray(x[:, 100:]), np.ascontiguousarray(s[:, 100:]), mu0, gsc_front, st_other, [1])
    assert after[3].tolist() == [W, W]


def test_gain_detectors_sharing_residuals_give_each_its_own_numbers(monkeypatch):
    """Two gain detectors over the same residuals (the monitor's front and rear checks) run in turn
    and alone give the same numbers."""
    rng = np.random.default_rng(11)
    x, s = _gain_data(rng, R=1, T=800)
    t = np.arange(x.shape[1]) * 0.02
    sig = Signals(t, np.concatenate([x, s[:, :, None]], axis=2), ["f", "r", "a", "v"])
    kw = dict(W=150, mu0=[1e-3, -2e-3, 0.0], sigma2=[0.0025] * 3, min_length=20, min_gain=0.003)
    front = sensor.GainDetector(["f", "r", "a"], "v", threshold=40.0, signature=[1, 0, 1], name="front",
                                rivals=[[0, 1, -1], [1, 1, 0]], **kw)
    rear = sensor.GainDetector(["f", "r", "a"], "v", threshold=30.0, signature=[0, 1, -1], name="rear",
                               rivals=[[1, 0, 1], [1, 1, 0]], gain_scale=[1.0, 1.0, 1.24], **kw)
    together = [d.run(sig).values for d in (front, rear, front, rear)]
    alone = []
    for d in (front, rear):
        monkeypatch.setattr(sensor.gain, "_GAIN_LAST", [None])
        alone.append(d.run(sig).values)
    for a, b in zip(together, alone * 2):
        assert np.array_equal(a.view(np.int64), b.view(np.int64))
    assert max(np.abs(v).max() for v in alone) > 0


# ---------------------------------------------------------------------------------- combination
def _combined_reference(gp, gm, sigma2, signature, rivals, thr, sides):
    """``DriftDetector._compute`` (``sides`` False, no rivals) and ``GainDetector._compute`` (with a
    signature) as they were: numpy over the scaled one-sided statistics."""
    gp, gm = gp / sigma2, gm / sigma2

    def combined(sig):
        use = sig != 0
        pos = sig[use] > 0
        return (
            np.where(pos, gp[..., use], gm[..., use]).min(axis=2),
            np.where(pos, gm[..., use], gp[..., use]).min(axis=2),
        )

    up, down = combined(signature)
    if not sides:
        return (np.maximum(up, down) / thr)[:, :, None]
    for rv in rivals:
        best = np.maximum(*combined(rv))
        up = np.where(best >= up, 0.0, up)
        down = np.where(best >= down, 0.0, down)
    up, down = up / thr, down / thr
    return np.stack([np.maximum(up, down), np.zeros_like(up), up, down], axis=2)


@pytest.mark.parametrize("seed", range(6))
def test_combine_kernel_is_bitwise_the_numpy_expressions(seed):
    """Ties (values from a small set), zeros, infinities and NaN (the kernels' statistics are >= +0
    or NaN, never -0.0), every signature and rivals."""
    rng = np.random.default_rng(300 + seed)
    R, T, C = 2, 400, int(rng.integers(1, 5))
    pool = np.array([0.0, 1.0, 2.0, 2.5, np.inf, np.nan])
    gp, gm = (
        np.where(rng.random((R, T, C)) < 0.5, rng.choice(pool, (R, T, C)), rng.exponential(3.0, (R, T, C)))
        for _ in range(2)
    )
    sigma2 = rng.uniform(0.5, 2.0, C)
    thr = float(rng.uniform(0.5, 5.0))

    def signature():
        while True:
            sg = rng.choice([-1.0, 0.0, 1.0], C)
            if sg.any():
                return sg

    sig = signature()
    rivals = [signature() for _ in range(int(rng.integers(0, 3)))]
    for sides in (False, True):
        ref = _combined_reference(gp, gm, sigma2, sig, [] if not sides else rivals, thr, sides)
        out = np.zeros((R, T, 4 if sides else 1))
        sigs = np.array([sig, *rivals]) if sides else sig[None, :]
        sensor._combine_kernel(gp, gm, sigma2, sigs, thr, sides, out)
        assert np.array_equal(out.view(np.int64), ref.view(np.int64))
    assert np.isnan(ref).any() and (ref == 0).any() and (ref > 0).any()


# ---------------------------------------------------------------------------------- step GLR
def test_step_comparison_is_settled_only_where_the_approximation_gives_the_exact_answer():
    """For single terms ``a^2 / L`` (exact) and ``a^2 * (1 / L)`` (approximate) and values ``v`` at,
    one or a few ulps around, and a relative 1e-13 .. 1e-9 away from either, ``_step_known`` may
    settle ``v <= G`` only where ``v <= g (1 - band)`` is its answer; and it must settle clear cases
    (else the approximation would be useless)."""
    rng = np.random.default_rng(5)
    a = rng.standard_normal(3000) * 10.0 ** rng.uniform(-3, 3, 3000)
    L = rng.integers(1, 1000, a.size).astype(float)
    # subnormal a^2 (where the approximation can be far off): the terms where it differs
    tiny = rng.uniform(1, 10, 200_000) * 10.0 ** rng.uniform(-162, -154, 200_000)
    Lt = rng.integers(3, 1000, tiny.size).astype(float)
    off = tiny * tiny / Lt != tiny * tiny * (1.0 / Lt)
    a = np.concatenate([a, tiny[off], tiny[:100], rng.standard_normal(100) * 1e-200, [0.0, 1e-300]])
    L = np.concatenate([L, Lt[off], Lt[:100], rng.integers(1, 1000, 102)]).astype(float)
    assert off.sum() > 50
    band = sensor._STEP_BAND
    differ = settled = 0
    for ai, Li in zip(a, L):
        sq = ai * ai
        G, g = sq / Li, sq * (1.0 / Li)
        differ += G != g
        vs = [0.0, G, g, np.nan, np.inf]
        for base in (G, g):
            x = base
            for _ in range(4):
                x = np.nextafter(x, np.inf)
                vs.append(x)
            x = base
            for _ in range(4):
                x = np.nextafter(x, -np.inf)
                vs.append(x)
            vs += [base * (1 + e) for e in (1e-13, -1e-13, 1e-11, -1e-11, 1e-9, -1e-9)]
        for v in vs:
            if sensor._step_known(v, g):
                settled += 1
                assert (v <= g * (1.0 - band)) == (v <= G) or (v == 0.0 and not G > 0), (ai, Li, v)
    assert differ > 500 and settled > 10000
