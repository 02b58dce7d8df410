"""The blocked window kernels of the drift and gain detectors against the per-sample kernels they
replace (issue 19).

``_ramp_reference`` and ``_gain_reference`` below are the kernels of ``fdikit.detect.sensor`` as
they were before issue 19: per sample, the sums over the last ``L = 1 .. n`` samples accumulated
backwards from the newest one, the GLR maximised over ``L``. The blocked kernels evaluate a block
of samples at once (candidates in the outer loop, samples in the inner, vectorised one) with each
sample's sums taken in the same order, so the outputs *and the ring-buffer states* must be
bitwise equal -- on random data in pieces of random length (one sample at a time as streaming
does, pieces shorter and longer than a block), with resets between pieces (what the monitor does
after a held gap), and through a monitor over a record with NaN-held gaps.
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
        k = min(T, k + int(rng.choice([1, 1, 3, 15, 16, 17, 255, 256, 257, 700])))
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
    monkeypatch.setattr(sensor, "_ramp_kernel", _ramp_reference)
    monkeypatch.setattr(sensor, "_gain_kernel", _gain_reference)
    ref = _monitor().run(rec)
    assert np.array_equal(fast.statistics.values, ref.statistics.values)
    assert np.nanmax(fast.statistics.values) > 1.0  # alarms: not a comparison of zeros
    key = lambda e: (e.run, e.k, e.hypothesis, e.value, e.kind)  # noqa: E731
    assert [key(e) for e in fast.events] == [key(e) for e in ref.events] and fast.events
