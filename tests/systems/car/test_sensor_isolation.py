"""Issue 27: the right sensor (generic peer checks of redundant groups) and the right fault type
(the fault-type classification stage), on synthetic data and on the real RAV4 minute."""

from pathlib import Path

import numpy as np
import pytest

from fdikit import Signals
from fdikit.detect import PeerCheck, design_peer_check
from fdikit.errors import DataError
from fdikit.isolate import FAULT_TYPES, FaultTypeClassifier

DATA = Path("../shared/data/rav4-highway")


def _wheels(seed=0, T=3000):
    rng = np.random.default_rng(seed)
    U = 20 + np.cumsum(rng.normal(0, 0.05, T))
    x = U[:, None] * [1.0, 1.01, 0.99, 1.0] + 0.01 * rng.standard_normal((T, 4))
    return np.arange(T) * 0.02, x


def _stream(stage, sig):
    stage.reset(sig.runs)
    x = sig.values[:, :, sig.index(stage.input_names)]
    return np.stack([stage.step(x[:, k]) for k in range(sig.n_samples)], axis=1)


def test_peer_check_names_the_member_batch_equals_streaming_and_round_trips():
    t, x = _wheels()
    names = ["a", "b", "c", "d"]
    pc = design_peer_check(Signals(t[:1500], x[None, :1500], names), {"w": names})
    for j in range(4):
        for g in (0.97, 1.03):                    # low and high alike: no side from a sign
            f = x.copy()
            f[2000:, j] *= g
            out = pc.run(Signals(t, f[None], names))
            iso = np.array([out[f"peer:{m}:isolated"][0] for m in names])
            assert iso[j, 2200:].all() and not np.delete(iso, j, axis=0).any(), (j, g)
    sig = Signals(t, f[None], names)
    assert np.array_equal(pc.run(sig).values, _stream(pc, sig))
    pc2 = PeerCheck.from_dict(pc.to_dict())
    assert np.array_equal(pc2.run(sig).values, pc.run(sig).values)
    pc.reset(1)
    pc.step(f[None, 0])
    z = pc._z.copy()
    with pytest.raises(DataError, match="not finite"):
        pc.step([[np.nan, 1.0, 1.0, 1.0]])
    assert np.array_equal(pc._z, z) and pc._k == 1


def _slipping_wheels(seed=0, T=4000, dt=0.02):
    """Four wheels whose speeds depend on the acceleration: wheel j reads ``U + s_j a U`` (the slip of
    a driven / braked wheel), ``U`` accelerating and braking in turn."""
    rng = np.random.default_rng(seed)
    t = np.arange(T) * dt
    a = 1.5 * np.sin(2 * np.pi * t / 14.0) + 0.5 * np.sin(2 * np.pi * t / 5.3)
    U = 18.0 + np.cumsum(a) * dt
    slip = np.array([0.012, 0.010, -0.004, -0.005])
    x = U[:, None] * (1.0 + slip * a[:, None]) + 0.005 * rng.standard_normal((T, 4))
    names = ["a", "b", "c", "d"]
    sq = np.median(x, axis=1) ** 2
    return Signals(t, np.column_stack([x, sq])[None], [*names, "sq"]), names


def test_peer_check_rate_terms_follow_the_slip_and_stream_like_batch():
    sig, names = _slipping_wheels()
    half = Signals(sig.t[:2000], sig.values[:, :2000], sig.names)
    plain = design_peer_check(half, {"w": names}, references={"w": ["sq"]})
    rated = design_peer_check(half, {"w": names}, references={"w": ["sq"]}, rates={"w": ["sq"]},
                              rate_hz=1.0, prefix="tpeer")
    assert rated.rate_channels == ["sq"] and len(rated.coef["a"]) == 4
    po, ro = plain.run(sig), rated.run(sig)
    assert "tpeer:a:e" in ro.names and "peer:a:e" not in ro.names
    held = slice(2200, None)
    # the slip term takes the acceleration-dependent part out (held-out half): several times smaller
    for m in names:
        assert np.std(ro[f"tpeer:{m}:e"][0, held]) < 0.5 * np.std(po[f"peer:{m}:e"][0, held]), m
    # a 1 % gain of "a": its slope on the reference is the gain with the slip term, not without
    f = sig.values.copy()
    f[0, 2500:, 0] *= 1.01
    fs = Signals(sig.t, f, sig.names)
    e, x = rated.run(fs)["tpeer:a:e"][0, 2600:], rated.run(fs)["tpeer:a:ref"][0, 2600:]
    assert abs(np.polyfit(x, e, 1)[0] - 0.01) < 0.003
    # step by step equals batch; the rate filter's state checkpoints and round-trips
    assert np.array_equal(rated.run(fs).values, _stream(rated, fs))
    r2 = PeerCheck.from_dict(rated.to_dict())
    assert r2.prefix == "tpeer" and np.array_equal(r2.run(fs).values, rated.run(fs).values)
    rated.reset(1)
    x_in = fs.values[:, :, fs.index(rated.input_names)]
    for k in range(300):
        rated.step(x_in[:, k])
    st = rated.get_state()
    rest = np.stack([rated.step(x_in[:, k]) for k in range(300, 400)], axis=1)
    r2.reset(1)
    r2.set_state(st)
    assert np.array_equal(np.stack([r2.step(x_in[:, k]) for k in range(300, 400)], axis=1), rest)
    # a state saved before the rate terms loads into a check without them
    plain.reset(1)
    old = {k: v for k, v in plain.get_state().items() if k != "_zr"}
    plain.set_state(old)
    with pytest.raises(DataError, match="expected"):
        r2.set_state({k: v for k, v in st.items() if k != "_zr"})


def test_peer_check_fit_hz_undoes_the_shrinkage_of_a_noisy_peer():
    """A member whose peers carry loud high-frequency noise: the sample-wise fit shrinks the gain on
    the peers (its prediction's block means move less than the member's); fitted low-passed
    (``fit_hz``) the block means agree, so a gain test on them sees no nominal slope."""
    rng = np.random.default_rng(5)
    T, dt = 6000, 0.02
    t = np.arange(T) * dt
    y = 0.02 * np.sin(2 * np.pi * t / 9.0) + 0.01 * np.sin(2 * np.pi * t / 3.1)
    x = np.column_stack([y + 0.0005 * rng.standard_normal(T)]
                        + [y + 0.03 * rng.standard_normal(T) for _ in range(3)])
    names = ["g", "p1", "p2", "p3"]
    sig = Signals(t, x[None], names)

    def block_slope(pc):
        out = pc.run(sig)
        P = pc.prefix
        ref, e = out[f"{P}:g:ref"][0, 3000:], out[f"{P}:g:e"][0, 3000:]
        rb, eb = ref.reshape(-1, 25).mean(axis=1), e.reshape(-1, 25).mean(axis=1)
        return np.polyfit(rb, eb, 1)[0]

    half = Signals(t[:3000], x[None, :3000], names)
    raw = design_peer_check(half, {"y": names}, announce=["g"])
    fit = design_peer_check(half, {"y": names}, announce=["g"], fit_hz=1.0)
    assert raw.coef["g"][1] < 0.6 < 0.9 < fit.coef["g"][1] < 1.1, (raw.coef["g"], fit.coef["g"])
    assert block_slope(raw) > 0.5 and abs(block_slope(fit)) < 0.1
    with pytest.raises(DataError, match="fit_hz"):
        design_peer_check(half, {"y": names}, fit_hz=-1.0)


@pytest.mark.parametrize("bad, match", [
    (dict(rates={"v": ["sq"]}), "rates name unknown groups"),
    (dict(rates={"w": "sq"}), "lists of channels"),
    (dict(rate_hz=0.0), "rate_hz must be > 0"),
    (dict(prefix="a:b"), "prefix"),
])
def test_peer_check_refuses_bad_rate_terms(bad, match):
    kw = dict(rates={"w": ["sq"]})
    kw.update(bad)
    n = 2 + len(kw["rates"].get("w", [])) if isinstance(kw["rates"].get("w"), list) else 3
    with pytest.raises(DataError, match=match):
        PeerCheck({"w": ["a", "b", "c"]}, {m: [0.0, 1.0] + [0.0] * (n - 2) for m in "abc"},
                  {m: 0.1 for m in "abc"}, 0.02, **kw)


def test_peer_check_coef_length_counts_the_rate_terms():
    with pytest.raises(DataError, match="3 finite numbers"):
        PeerCheck({"w": ["a", "b", "c"]}, {m: [0.0, 1.0] for m in "abc"}, {m: 0.1 for m in "abc"}, 0.02,
                  rates={"w": ["sq"]})


def _classify(kind, seed=1):
    """Residual and reference of a synthetic sensor fault from sample 500 (isolated from 550)."""
    rng = np.random.default_rng(seed)
    T = 1500
    k = np.arange(T)
    ref = 0.05 * np.sin(k / 40.0)
    e = 0.002 * rng.standard_normal(T)
    raw = ref + e
    on = k >= 500
    if kind == "bias":
        e = e + 0.02 * on
    elif kind == "drift":
        e = e + 1e-4 * np.maximum(k - 500, 0)
    elif kind == "gain":
        e = e + 0.5 * ref * on
    elif kind == "stuck":
        raw = np.where(on, raw[500], raw)
        e = np.where(on, raw[500] - ref, e)
    elif kind == "intermittent":
        e = e + 0.02 * (on & ((k - 500) % 100 < 25))
    stat = np.abs(e) / 0.01
    iso = (stat >= 1) & on & (k >= 550)
    vals = np.column_stack([iso, stat, e, ref, raw])[None]
    return Signals(k * 0.02, vals, ["peer:s:isolated", "peer:s", "peer:s:e", "peer:s:ref", "raw:s"])


@pytest.mark.parametrize("kind", ["bias", "drift", "gain", "stuck", "intermittent"])
def test_fault_type_classifier_on_synthetic_faults(kind):
    sig = _classify(kind)
    ftc = FaultTypeClassifier(["s"], {"s": 0.002}, 1000, raw={"s": "raw:s"}, stuck_after={"s": 50},
                              lookback=100, burst_gap=25, clear_after=250)
    out = ftc.run(sig)
    assert out[f"s:{kind}"][0, -1] == 1.0, {t: out[f"s:{t}"][0, -1] for t in FAULT_TYPES}
    assert out["s:active"][0, :500].max() == 0.0
    assert np.array_equal(out.values, _stream(ftc, sig))
    ftc2 = FaultTypeClassifier.from_dict(ftc.to_dict())
    assert np.array_equal(ftc2.run(sig).values, out.values)


def test_fault_type_classifier_refuses_nan_before_state_changes():
    ftc = FaultTypeClassifier(["s"], {"s": 0.1}, 100, raw={"s": "raw:s"}, stuck_after={"s": 5})
    ftc.reset(1)
    ftc.step([[0.0, 0.1, 0.0, 1.0, 2.0]])
    before = {a: np.copy(getattr(ftc, a)) for a in ftc._state_attrs}
    with pytest.raises(DataError, match="not finite"):
        ftc.step([[0.0, np.nan, 0.0, 1.0, 2.0]])
    assert all(np.array_equal(before[a], getattr(ftc, a), equal_nan=True) for a in ftc._state_attrs)


def test_a_blip_before_a_step_is_no_burst_but_two_ended_bursts_are():
    """The block-mean burst rule: a nominal blip in the lookback window followed by a step is one
    episode while the step lasts (a bias, not an intermittent fault); bursts below the detection
    level (the sample rule does not see them) that end are an intermittent fault once the second
    has ended."""
    k = np.arange(1500)
    rng = np.random.default_rng(3)
    ref = 0.05 * np.sin(k / 40.0)

    def typed(e, iso, at):
        stat = np.abs(e) / 0.01
        sig = Signals(k * 0.02, np.column_stack([iso, stat, e, ref, ref + e])[None],
                      ["peer:s:isolated", "peer:s", "peer:s:e", "peer:s:ref", "raw:s"])
        ftc = FaultTypeClassifier(["s"], {"s": 0.002}, 600, lookback=120, min_len=5, sigma_block={"s": 0.001})
        out = ftc.run(sig)
        return [[t for t in FAULT_TYPES if out[f"s:{t}"][0, j] == 1.0] for j in at]

    e = 0.0003 * rng.standard_normal(k.size) + 0.02 * (k >= 500)
    e[450:460] += 0.006                          # one block-long blip, below detection, then the step
    assert typed(e, (np.abs(e) >= 0.01) & (k >= 550), [700, 1000]) == [["bias"], ["bias"]]
    e = 0.0003 * rng.standard_normal(k.size)
    on = (k >= 500) & ((k - 500) % 60 < 10)      # 10-sample bursts every 60 samples, below detection
    e[on] += 0.006
    got = typed(e, k >= 550, [565, 640])         # the second burst still on / ended
    assert got == [["bias"], ["intermittent"]], got


# --- the real RAV4 minute -------------------------------------------------------------------------

WHEELS = ["wheel_fl", "wheel_fr", "wheel_rl", "wheel_rr"]
_SENSORS = set(WHEELS) | {"yaw_rate", "lateral_accelerometer", "steering"}


def _named(res):
    """(t, sensor, type) of the announcements and changes (a revised type of an open episode) that
    name one sensor and a fault type."""
    out = []
    for a in sorted(res["announcements"] + res.get("changes", []), key=lambda a: a["t"]):
        s, _, typ = a["fault"].partition(":")
        if typ and s in _SENSORS:
            out.append((a["t"], s, typ))
    return out


@pytest.fixture(scope="module")
def run():
    if not (DATA / "drive.blf").exists():
        pytest.skip("RAV4 data not available")
    from fdikit.systems.car.monitor_rav4 import run_rav4_log

    return lambda spec: run_rav4_log(str(DATA), spec)


@pytest.mark.parametrize("gain", [0.985, 1.015])
@pytest.mark.parametrize("wheel", WHEELS)
def test_wheel_gain_names_that_wheel(run, wheel, gain):
    res = run(f"gain:WHEEL_SPEED_{wheel[-2:].upper()}:{gain}@40")
    named = _named(res)
    assert named, res["announcements"]
    assert {s for _t, s, _ty in named} == {wheel}, named
    assert res["false_announcements"] == []


@pytest.mark.parametrize(("spec", "kind"), [("bias:YAW_RATE:2@40", "bias"),
                                             ("drift:YAW_RATE:0.2/s@40", "drift"),
                                             ("gain:YAW_RATE:3@10", "gain"), ("stuck:YAW_RATE@40", "stuck")])
def test_yaw_rate_fault_type(run, spec, kind):
    res = run(spec)
    named = [(t, ty) for t, s, ty in _named(res) if s == "yaw_rate"]
    assert named, res["announcements"]
    assert {s for _t, s, _ty in _named(res)} == {"yaw_rate"}
    # the type settled within 5 s of the first typed announcement (the stage may revise it)
    t0 = named[0][0]
    settled = [ty for t, ty in named if t <= t0 + 5.0][-1]
    assert settled == kind, named


@pytest.mark.parametrize(("spec", "kind"), [("gain:YAW_RATE:0.5@40", "gain"), ("gain:YAW_RATE:2@40", "gain"),
                                             ("gain:YAW_RATE:3@45", "gain"),
                                             ("bias:YAW_RATE:0.5@40", "bias")])
def test_yaw_rate_gain_on_the_straight_is_typed_by_the_gyro_offset(run, spec, kind):
    """Issue 27: on the held-out straight the yaw rate moves by +-0.2 deg/s, and a gain's residual is
    mostly the gain times the gyro's offset (-0.38 deg/s, removed by the conditioning): x0.5 and x3
    were typed bias, x2 (its residual crossing the threshold as the yaw rate moves) intermittent.
    The stage's gain through the fault-free level, offset included (``GAIN_OFFSETS``), types them
    gain; a bias of the same size stays a bias. The final type counts (it may be revised)."""
    res = run(spec)
    named = [(t, ty) for t, s, ty in _named(res) if s == "yaw_rate"]
    assert named and {s for _t, s, _ty in _named(res)} == {"yaw_rate"}, _named(res)
    assert named[-1][1] == kind, named


def test_steering_stuck_wait_exceeds_every_fault_free_run_of_the_minute():
    """The steering stuck check waits (``stuck_after``, designed on the calibration half: its
    longest run of equal STEER_ANGLE samples, 5.78 s, times 2) longer than the longest fault-free
    run of the whole minute (7.82 s, in the held-out half): a smaller ``stuck_margin`` (below 0.36)
    would announce a stuck steering on the fault-free minute (issue 27: why the steering stuck
    check takes 11 s where the angle does not move)."""
    if not (DATA / "drive.blf").exists():
        pytest.skip("RAV4 data not available")
    from fdikit.systems.car.monitor_rav4 import rav4_monitor

    mon = rav4_monitor(str(DATA))
    x = mon.raw["steer_angle"][0]
    t = mon.raw.t - mon.raw.t[0]

    def longest(same):
        run = top = 0
        for s in same:
            run = run + 1 if s else 0
            top = max(top, run)
        return top

    whole = longest(np.diff(x) == 0)                              # equal increments, whole minute
    cal = longest(np.diff(x[(t >= 5.0) & (t <= mon.record["half_s"])]) == 0)
    wait = mon.record["peer_checks"]["stuck_after"]["sig:steering"]
    assert cal < whole, (cal, whole)                              # the held-out half's run is longer
    assert wait == int(np.ceil((cal + 1) * 2.0)), (wait, cal)     # stuck_margin = 1
    assert wait > whole + 1, (wait, whole)
