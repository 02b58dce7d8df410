"""Passenger-car health monitor (ng-chen-speyer, Sections IV-V): filters, parity equations, features, the
assembled monitors, the pattern table and the experiments."""

from __future__ import annotations

import argparse

import numpy as np
import pytest

from fdikit import Signals
from fdikit.detect.mhsspt import calibrate_densities
from fdikit.residuals import internal_form
from fdikit.residuals.fdf import filter_frequency_response
from fdikit.systems.car.monitor import (
    FILTER_SETS,
    LATERAL_SETS,
    LONGITUDINAL_SETS,
    FeatureNorms,
    OffsetFilter,
    ParityEquations,
    build_monitor,
    design_car_monitor,
    pattern_table,
)


@pytest.fixture(scope="module")
def des():
    return design_car_monitor(20.0)


def _plant_response(model, group, z):
    """Discrete plant response (F, p, k) of one input group at the points z, by direct solves."""
    A, B, C, D = model.A, model.B_of(group), model.C, model.D_of(group)
    n = A.shape[0]
    return np.array([C @ np.linalg.solve(zi * np.eye(n) - A, B) + D for zi in z])


def _response(M, group, z):
    return _plant_response(M, group, z)


FREQS = np.r_[0.0, np.linspace(0.05, 5.0, 40)]


@pytest.mark.parametrize("s", sorted(FILTER_SETS))
def test_nuisance_blocked_dc_to_5hz(des, s):
    """Nuisance-to-residual transmission <= 1e-3 of target-to-residual at DC and across 0-5 Hz, from
    the recomputed internal form AND from the plant and filter responses composed by hand."""
    model = des.models["longitudinal" if s in LONGITUDINAL_SETS else "lateral"]
    z = np.exp(2j * np.pi * FREQS * des.dt)
    for target, d in des.designs[s].items():
        nuisance = [o for o in FILTER_SETS[s] if o != target]
        if s in LONGITUDINAL_SETS:
            nuisance.append("nonlinearity:1")
        M = internal_form(d, model)
        Gf = _response(M, "f", z)                       # (F, q, k) from the recomputed internal form
        jt = M.fault_names.index(target)
        jn = [M.fault_names.index(n) for n in nuisance]
        tgt = np.linalg.norm(Gf[:, :, jt], axis=1).max()
        assert tgt > 0
        # exact UIO: the nuisance is zero to rounding at every frequency
        nu = np.abs(Gf[:, :, jn]).max()
        assert nu <= 1e-3 * tgt, (s, target, nu, tgt)
        assert nu <= 1e-8 * tgt, (s, target, nu, tgt)
        # independent composition: filter response x plant response (faults enter through y only)
        _Gu, Gy = filter_frequency_response(d, FREQS)
        Gp = _plant_response(model, "f", z)[:, model.output_index(d.y_names)]
        Gc = Gy @ Gp
        assert np.allclose(Gc, Gf, atol=1e-8 * max(1.0, np.abs(Gf).max()))
        # the target reaches the residual at DC
        assert np.linalg.norm(Gf[0, :, jt]) > 1e-6 * np.linalg.norm(Gf[0])


def test_slope_blocked_where_separable(des):
    """The road slope is a nuisance of sets 1-3 where it is separable; where it is blocked its
    transmission is zero too."""
    model = des.models["longitudinal"]
    z = np.exp(2j * np.pi * FREQS * des.dt)
    blocked = des.info["slope_blocked"]
    for s in LONGITUDINAL_SETS:
        for target, d in des.designs[s].items():
            if not blocked[f"set{s}/{target}"]:
                continue
            M = internal_form(d, model)
            Gd = _response(M, "d", z)
            Gf = _response(M, "f", z)[:, :, M.fault_names.index(target)]
            assert np.abs(Gd).max() <= 1e-8 * np.abs(Gf).max()


def test_parity_equations_closed_form():
    dt, tau = 0.01, 0.1
    pe = ParityEquations(dt, tau)
    T = 50
    t = np.arange(T) * dt
    u = np.zeros((1, T, 2))
    u[0, :, 0] = 12.0
    u[0, :, 1] = 1.0                 # brake command step at k = 0
    y = np.zeros((1, T, 2))
    y[0, :, 0] = 12.0 + 0.7          # throttle sensor bias 0.7
    sig = Signals(t, np.concatenate([u, y], axis=2), ["throttle", "brake", "throttle_meas", "brake_meas"])
    r = pe.run(sig)
    assert np.allclose(r["parity1"][0], 0.7)
    # brake measurement 0 while the model expects 1 - exp(-k dt / tau)
    assert np.allclose(r["parity2"][0], -(1.0 - np.exp(-t / tau)), atol=1e-12)
    pe.reset(1)
    st = np.array([pe.step(u[0, k], y[0, k])[0] for k in range(T)])
    assert np.array_equal(st, r.values[0])


def test_feature_norms_and_offset_filter_batch_equals_stream(des):
    rng = np.random.default_rng(0)
    names = [f"r{i}" for i in range(5)]
    x = rng.normal(size=(2, 40, 5))
    fn = FeatureNorms({"a": names[:3], "b": names[3:]}, dt=0.01, tau=0.05)
    out = fn.run(Signals(np.arange(40) * 0.01, x, names)).values
    alpha = 1 - np.exp(-0.01 / 0.05)
    ref = np.zeros((2, 2))
    for k in range(40):  # independent recursion
        n = np.stack([np.linalg.norm(x[:, k, :3], axis=1), np.linalg.norm(x[:, k, 3:], axis=1)], 1)
        ref = ref + alpha * (n - ref)
        assert np.allclose(out[:, k], ref, rtol=1e-13)
    fn.reset(2)
    st = np.stack([fn.step(x[:, k]) for k in range(40)], 1)
    assert np.array_equal(st, out)
    d = des.designs[1]["sensor:a_x"]
    f = OffsetFilter(d, np.full(len(d.u_names), 3.0), np.full(len(d.y_names), -1.0))
    T = 30
    v = rng.normal(size=(2, T, len(d.u_names) + len(d.y_names)))
    sig = Signals(np.arange(T) * d.dt, v, d.u_names + d.y_names)
    b = f.run(sig).values
    f.reset(2)
    s = np.stack([f.step(v[:, k, :len(d.u_names)], v[:, k, len(d.u_names):]) for k in range(T)], 1)
    assert np.array_equal(b, s)
    # the offset is a plain shift of the inputs
    from fdikit.residuals import FaultDetectionFilter
    sh = v.copy()
    sh[:, :, :len(d.u_names)] -= 3.0
    sh[:, :, len(d.u_names):] += 1.0
    assert np.array_equal(FaultDetectionFilter(d).run(Signals(sig.t, sh, sig.names)).values, b)


def _synthetic_monitor(des, block):
    """A monitor with densities calibrated on synthetic features (no simulation)."""
    from fdikit.systems.car.monitor import _generators

    _gens, groups = _generators(des, block)
    C = len(groups)
    rng = np.random.default_rng(1)
    nominal = np.abs(rng.normal(0.2, 0.05, (200, C)))
    faults = {}
    for j, name in enumerate(["f0", "f1"]):
        faults[name] = {m: nominal[:50] + m * np.eye(C)[j] for m in (1.0, 2.0, 3.0)}
    return build_monitor(des, block, calibrate_densities(nominal, faults), warmup=0.1)


@pytest.mark.parametrize("block", ["longitudinal", "lateral"])
def test_monitor_batch_equals_stream(des, block):
    from fdikit.faults import Bias
    from fdikit.systems.car.driving import simulate_drive
    from fdikit.systems.car.monitor import car_signals, sensor_noise

    mon = _synthetic_monitor(des, block)
    res = simulate_drive("straight", 20.0, duration=0.6, dt=5e-3, runs=2, noise=sensor_noise(),
                         faults=[Bias("sensor:a_x", [0.0, 0.8], start=0.3)])
    sig = car_signals(res)
    b = mon.monitor.run(sig)
    s = mon.monitor.stream(sig)
    assert np.array_equal(b.residuals.values, s.residuals.values)
    assert np.allclose(b.statistics.values, s.statistics.values, rtol=1e-12, atol=1e-14)
    assert [(e.run, e.k, e.hypothesis) for e in b.events] == [(e.run, e.k, e.hypothesis) for e in s.events]
    sets = LONGITUDINAL_SETS if block == "longitudinal" else LATERAL_SETS
    n_parity = 2 if block == "longitudinal" else 0
    assert len(mon.monitor.residual_names) == sum(len(d.residual_names) for d in des.filters(sets)) + n_parity


def test_monitor_hypothesis_counts():
    """15 longitudinal hypotheses (H0 + 7 faults x small/large), 11 lateral (paper Section IV-E)."""
    from fdikit.systems.car.monitor import LATERAL_FAULTS, LONGITUDINAL_FAULTS

    assert 1 + 2 * len(LONGITUDINAL_FAULTS) == 15
    assert 1 + 2 * len(LATERAL_FAULTS) == 11


@pytest.fixture(scope="module")
def pt(des):
    return pattern_table(20.0, kind="straight", duration=4.5, onset=2.0)


def test_pattern_table_rows_distinct(pt):
    rows = {k: tuple(v) for k, v in pt["rows"].items() if k != "throttle_actuator"}
    assert all(any(v) for v in rows.values()), pt["text"]
    # binary patterns: the longitudinal hypotheses are all distinct
    lon = ["throttle", "brake_actuator", "brake_sensor", "engine_speed", "accelerometer", "front_wheel_sum",
           "rear_wheel_sum"]
    assert len({rows[k] for k in lon}) == len(lon), pt["text"]
    # graded patterns (the MHSSPT's view): no two hypotheses' responses are parallel; recomputed here
    j1, j2 = pt["columns"].index("|parity1|"), pt["columns"].index("|parity2|")
    for k in ("throttle", "throttle_actuator"):
        assert pt["rows"][k][j1] == 1 and pt["rows"][k][j2] == 0
    for k in ("brake_actuator", "brake_sensor"):
        assert pt["rows"][k][j2] == 1 and pt["rows"][k][j1] == 0


def test_lateral_patterns_not_parallel(pt):
    """The lateral filters block a sensor nuisance by not reading it (output projection) and their
    residuals are whitened: the front and rear wheel-speed-difference faults no longer give parallel
    patterns (cosine 0.999 with the state-space blocking [f, A f] and raw norms; 0.90 now)."""
    lat = ["steering_actuator", "lateral_accelerometer", "yaw_rate", "front_wheel_diff", "rear_wheel_diff"]
    Z = np.array([np.clip(pt["ratio"][k], 0, None) for k in lat])
    Z /= np.linalg.norm(Z, axis=1, keepdims=True)
    cos = Z @ Z.T - 2 * np.eye(len(lat))
    assert cos.max() < 0.95, cos.max()
    # every lateral fault has its own binary row, with a zero where the filter blocking it sits
    rows = {k: tuple(pt["rows"][k]) for k in lat}
    assert len(set(rows.values())) == len(lat), pt["text"]


def test_lateral_filters_one_per_blocked_fault(des):
    """The exact UIO depends on its nuisance only: set 6's accelerometer filter (nuisance the rear
    wheel-speed difference) is set 5's yaw-rate filter and gives no feature of its own; the five
    lateral features block the five lateral faults one each (the nuisance transmission recomputed
    from the internal form, the target's and the other faults' from the plant)."""
    a, b = des.designs[6]["sensor:a_y"], des.designs[5]["sensor:yaw_rate"]
    assert np.allclose(a.C, b.C) and np.allclose(a.Dy, b.Dy) and np.allclose(a.By, b.By)
    groups = des.residual_groups(LATERAL_SETS)
    assert "|set6/sensor:a_y|" not in groups and len(groups) == 5
    assert len(des.residual_groups(LATERAL_SETS, unique=False)) == 6
    # longitudinal: set 3's brake filter has set 2's front-wheel filter's nuisance (rear wheel-speed
    # sum, nonlinearity) and is the same filter
    lon = des.residual_groups(LONGITUDINAL_SETS)
    assert "|set3/actuator:brake|" not in lon and len(lon) == 5
    nuis = [des.designs[s][t].info["nuisance"] for s, t in ((3, "actuator:brake"), (2, "sensor:w_front_sum"))]
    assert nuis[0] == nuis[1], nuis
    model = des.models["lateral"]
    z = np.exp(2j * np.pi * FREQS * des.dt)
    blocked = []
    for s in LATERAL_SETS:
        for target, d in des.designs[s].items():
            if f"|{d.residual_names[0].rsplit(':', 1)[0]}|" not in groups:
                continue
            Gf = np.abs(_response(internal_form(d, model), "f", z)).max(axis=(0, 1))  # per fault
            blocked.append(model.fault_names[int(np.argmin(Gf))])
            assert np.sort(Gf)[1] > 1e6 * Gf.min(), (s, target, Gf)   # one fault blocked, all others seen
    assert sorted(blocked) == sorted(model.fault_names)


def test_lateral_residuals_whitened(des):
    """The whitened lateral residuals have unit covariance on their range under the sensor noise:
    sample covariance of the filters driven by simulated white noise (independent of the Lyapunov
    equation used to whiten)."""
    from fdikit.residuals import FaultDetectionFilter
    from fdikit.systems.car.monitor import SENSOR_NOISE_STD

    rng = np.random.default_rng(3)
    for s in LATERAL_SETS:
        for d in des.designs[s].values():
            T = 40000
            v = rng.normal(size=(1, T, len(d.y_names))) * np.array([SENSOR_NOISE_STD[y] for y in d.y_names])
            u = np.zeros((1, T, len(d.u_names)))
            sig = Signals(np.arange(T) * d.dt, np.concatenate([u, v], axis=2), d.u_names + d.y_names)
            r = FaultDetectionFilter(d).run(sig).values[0, 2000:]
            w = np.linalg.eigvalsh(np.cov(r.T))
            k = d.info["noise_rank"]
            assert np.allclose(w[-k:], 1.0, atol=0.05), (s, w)
            assert np.all(w[:-k] < 1e-6), (s, w)


def test_steering_separates_from_accelerometer(des):
    """Root cause of the steering shortfall: a steering step enters the lateral acceleration
    instantly (the tyre force, D = 67 m/s^2/rad), so at the first sample it is an accelerometer bias;
    only the yaw dynamics tell them apart. The residual that blocks the accelerometer must see the
    smallest calibrated steering fault (0.01 rad) within a few samples, in noise standard deviations
    (whitened): step response of the recomputed internal form, by direct recursion."""
    model = des.models["lateral"]
    d = des.designs[6]["sensor:w_rear_diff"]
    M = internal_form(d, model)
    js, ja = M.fault_names.index("actuator:steer"), M.fault_names.index("sensor:a_y")
    x, xa = np.zeros(M.n_states), np.zeros(M.n_states)
    steer, acc = [], []
    for _ in range(6):
        steer.append(np.linalg.norm((M.C @ x + M.D_of("f")[:, js]) * 0.01))
        acc.append(np.linalg.norm(M.C @ xa + M.D_of("f")[:, ja]))
        x = M.A @ x + M.B_of("f")[:, js]
        xa = M.A @ xa + M.B_of("f")[:, ja]
    assert max(acc) < 1e-9                   # the accelerometer is blocked
    assert steer[0] < 0.2                    # the first sample cannot tell them apart
    assert steer[1] > 1.5 and steer[3] > 5.0, steer   # the yaw dynamics can, within 30 ms
    # the plant itself: steer -> a_y feedthrough (what makes the first sample ambiguous)
    iy = model.output_index(["a_y"])[0]
    assert model.D_of("f")[iy, model.fault_names.index("actuator:steer")] > 50.0


def test_cli_parser():
    from fdikit.commands.car_monitor import add_monitor_parsers

    p = argparse.ArgumentParser()
    add_monitor_parsers(p.add_subparsers(dest="car_action"))
    a = p.parse_args(["scenario", "steering_actuator", "--json", "--plot", "x.png"])
    assert (a.name, a.json, a.plot) == ("steering_actuator", True, "x.png")
    assert p.parse_args(["scenario", "--list"]).list
    assert p.parse_args(["monitor-log", "d", "--inject", "yaw_rate:0.03@20"]).inject == "yaw_rate:0.03@20"


def _feature_calibrated_monitors(des):
    """Both monitors with densities calibrated on the features of a short simulation (one fault
    per block), so that the test sees real detections."""
    from fdikit.faults import Bias
    from fdikit.monitor import Monitor
    from fdikit.systems.car.driving import simulate_drive
    from fdikit.systems.car.monitor import _generators, car_signals, sensor_noise

    res = simulate_drive("straight", 20.0, duration=1.6, dt=5e-3, runs=3, noise=sensor_noise(), seed=4,
                         faults=[Bias("sensor:a_x", [0.0, 1.0, 0.0], start=0.7),
                                 Bias("sensor:yaw_rate", [0.0, 0.0, 0.05], start=0.7)])
    sig = car_signals(res)
    t = sig.t
    mons = []
    for block, run in (("longitudinal", 1), ("lateral", 2)):
        gens, groups = _generators(des, block)
        X = Monitor(gens, [FeatureNorms(groups, des.dt, 0.0)]).run(sig).statistics.values
        nominal = X[0, t >= 0.3]
        f = X[run, t >= 0.8]
        cal = calibrate_densities(nominal, {f"f_{block}": {1.0: f, 1.1: 1.1 * f, 1.2: 1.2 * f}},
                                  no_fault=f"none:{block}", inflate=1.5)
        mons.append(build_monitor(des, block, cal, warmup=0.3))
    return mons, sig


def test_fused_monitor_equals_stagewise(des):
    from fdikit.systems.car.monitor_fused import FusedCarMonitor

    mons, sig = _feature_calibrated_monitors(des)
    fused = FusedCarMonitor(mons)
    assert fused.table_error < 2e-4
    out = fused.run(sig)
    seen = 0
    for m in mons:
        st = m.monitor.run(sig).statistics
        for f in m.faults:
            # tabulated densities: probabilities agree to the interpolation error's effect
            assert np.abs(out[f"P:{f}"] - st[f"P:{f}"]).max() < 1e-3, f
            assert np.array_equal(out[f"A:{f}"], st[f"P:{f}:alarm"]), f
            seen += int(st[f"P:{f}:alarm"].max() > 0)
    assert seen == 2  # each block announced its fault in its faulty run
    fused.reset(sig.runs)
    V = sig.values[:, :, sig.index(fused.input_names)]
    st = np.stack([fused.step(V[:, k]) for k in range(sig.n_samples)], 1)
    assert np.array_equal(st, out.values)


@pytest.mark.slow
@pytest.mark.parametrize("name,delay", [("brake_actuator_short", 0.5), ("brake_actuator", 0.5),
                                        ("steering_actuator", 0.2)])
def test_actuator_scenarios(name, delay):
    from fdikit.systems.car.scenarios import run_scenario

    s = run_scenario(name)["summary"]
    assert s["isolated"] == s["fault"], s
    assert s["detection_delay_s"] is not None and s["detection_delay_s"] <= delay, s
    assert not s["false_announcements"], s


@pytest.mark.slow
def test_intermittent_front_wheel_sensor():
    from fdikit.systems.car.scenarios import run_scenario

    s = run_scenario("intermittent_front_wheel")["summary"]
    assert not s["false_announcements"], s
    for w in s["windows"]:
        assert w["rise_delay_s"] is not None and w["rise_delay_s"] <= 0.2, w
        assert w["fall_delay_s"] is not None and w["fall_delay_s"] <= 0.5, w


@pytest.mark.slow
def test_accelerometer_delay_falls_with_the_bias():
    """Paper Fig. 4: the larger the bias, the shorter the delay."""
    from fdikit.systems.car.scenarios import run_scenario

    d = [run_scenario(f"accel_bias_{b}")["summary"] for b in ("0.4", "0.6", "0.8")]
    assert all(s["isolated"] == "accelerometer" and not s["false_announcements"] for s in d), d
    delays = [s["detection_delay_s"] for s in d]
    assert delays[0] > delays[1] > delays[2], delays


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason=(
    "known shortfall: the 're-tuned faster' accelerometer filter (100x Riccati state weight) detects the "
    "0.6 m/s^2 bias in 0.55 s, the default in 0.15 s. In this exact UIO the bias reaches the residual "
    "only through the integration of the acceleration against the wheel speeds: the first 10 samples of "
    "its response do not depend on the weight, and a larger weight lowers the settled response (whitened "
    "5.95 -> 0.88 per 0.6 m/s^2: the observer absorbs the bias) while shortening its rise (63 %: 0.25 -> "
    "0.09 s). The paper's faster-but-noisier filter needs the target weighting of the optimal stochastic "
    "filter, which fdf.py does not model"))
def test_faster_accelerometer_filter_detects_sooner():
    """Paper Fig. 4, second column: the re-tuned filter detects the 0.6 m/s^2 bias sooner."""
    from fdikit.systems.car.scenarios import run_scenario

    d = [run_scenario(n)["summary"] for n in ("accel_bias_0.6", "accel_bias_0.6_fast")]
    assert all(s["isolated"] == "accelerometer" and not s["false_announcements"] for s in d), d
    assert d[1]["detection_delay_s"] < d[0]["detection_delay_s"], [s["detection_delay_s"] for s in d]


# ---------------------------------------------------------------------------------- real RAV4 minute
def _rav4_available():
    from fdikit.systems.car.rav4 import default_data_path

    return (default_data_path() / "drive.blf").exists()


rav4 = pytest.mark.skipif(not _rav4_available(), reason="RAV4 data not found")


@rav4
def test_rav4_filters_block_their_nuisance():
    """The noise-scaled designs, folded back to the measurement units, still block their nuisance
    exactly: internal form against the UNSCALED fitted model, DC to 5 Hz."""
    from fdikit.systems.car.monitor_rav4 import rav4_monitor

    mon = rav4_monitor()
    model = mon.model
    z = np.exp(2j * np.pi * FREQS * mon.record["dt"])
    for s, ds in mon.designs.items():
        for target, d in ds.items():
            M = internal_form(d, model)
            Gf = _response(M, "f", z)
            jt = M.fault_names.index(target)
            jn = [M.fault_names.index(o) for o in FILTER_SETS[s] if o != target]
            tgt = np.abs(Gf[:, :, jt]).max()
            assert tgt > 0
            assert np.abs(Gf[:, :, jn]).max() <= 1e-8 * tgt, (s, target)


@rav4
@pytest.mark.parametrize("spec,fault", [("wheel_rl:0.6@40", "rear_wheel_diff"),
                                        ("yaw_rate:0.03@40", "yaw_rate:bias")])
def test_rav4_injected_faults_isolated(spec, fault):
    """Faults injected into the held-out half of the real minute are announced and isolated (the yaw
    bias by the peer checks, with its type: the MHSSPT's unspecific ``yaw_rate`` waits for that
    evidence, ``Decision(confirm_after=...)``, issue 27)."""
    from fdikit.systems.car.monitor_rav4 import run_rav4_log

    r = run_rav4_log(None, spec)
    assert r["isolated"] == fault, r
    assert r["detection_delay_s"] is not None and r["detection_delay_s"] <= 0.5, r
    after = [a for a in r["announcements"] if a["t"] >= 40.0]
    assert after and after[0]["fault"] == fault, r


@rav4
def test_rav4_no_false_announcements():
    from fdikit.systems.car.monitor_rav4 import run_rav4_log

    assert run_rav4_log(None, "none")["announcements"] == []


@pytest.mark.slow
def test_ten_minute_nominal_drive_no_false_announcement():
    """Issue 8, item 7: 10 minutes over the scenarios' speed profiles (straight, speed steps, curve;
    20 and 24 m/s), both monitors: no announcement."""
    from fdikit.systems.car.scenarios import nominal_drive

    r = nominal_drive(10.0)
    assert abs(r["simulated_s"] - 600.0) < 1.0
    assert r["false_announcements"] == 0, r["segments"]


def test_sensor_nuisance_blocked_by_projection_keeps_the_other_wheel(des):
    """Blocking the front wheel-speed difference through its state-space equivalent [f, A f] also
    hides most of the rear wheel-speed difference's fault; projecting the front sensor out does not.
    DC gain of the whitened residual of the filter blind to the front sensor (set 4, target steering)
    to a 0.6 rad/s rear bias, from the internal form: C (I - A)^-1 B + D."""
    from fdikit.systems.car.monitor import design_car_monitor

    def dc(d):
        M = internal_form(d, des.models["lateral"])
        j = M.fault_names.index("sensor:w_rear_diff")
        g = M.C @ np.linalg.solve(np.eye(M.n_states) - M.A, M.B_of("f")[:, j]) + M.D_of("f")[:, j]
        jf = M.fault_names.index("sensor:w_front_diff")
        gf = M.C @ np.linalg.solve(np.eye(M.n_states) - M.A, M.B_of("f")[:, jf]) + M.D_of("f")[:, jf]
        assert np.linalg.norm(gf) < 1e-8 * max(1.0, np.linalg.norm(g))   # the front sensor is blocked
        return 0.6 * np.linalg.norm(g)

    state = design_car_monitor(20.0, lateral_sensor_nuisance="state")
    g_out, g_state = dc(des.designs[4]["actuator:steer"]), dc(state.designs[4]["actuator:steer"])
    assert g_out > 5.0 and g_state < 3.0, (g_out, g_state)


def test_extend_ranges_path_clips_the_rise_to_the_way_from_no_fault():
    """With ``path`` (the no-fault mean) a hypothesis's range covers the rise between the no-fault
    mean and its settled range, and neither an overshoot above the settled range nor a window below
    the no-fault mean; without it the whole rise. Hand-computed boxes, two features."""
    from fdikit.detect import UniformMeanGaussian
    from fdikit.detect.mhsspt import MHSSPTCalibration
    from fdikit.systems.car.monitor import extend_ranges

    cal = MHSSPTCalibration({"none": UniformMeanGaussian([1.0, 1.0], [1.0, 1.0], [0.1, 0.1]),
                             "f:small": UniformMeanGaussian([2.0, 0.9], [3.0, 1.1], [0.1, 0.1]),
                             "f:large": UniformMeanGaussian([4.0, 0.9], [5.0, 1.1], [0.1, 0.1])},
                            {"f": ["f:small", "f:large"]}, {})
    # feature 0 rises 1 -> 2.5 with a spike to 9 at the onset; feature 1 (not moved) is noise
    rise = {"f": {1.0: np.array([[9.0, 1.4], [1.5, 0.7], [2.5, 1.0]]),
                  2.0: np.array([[1.2, 1.3]]), 3.0: np.array([[4.5, 0.6]])}}
    box = extend_ranges(cal, rise)
    assert box.densities["f:small"].low.tolist() == [1.2, 0.7]
    assert box.densities["f:small"].high.tolist() == [9.0, 1.4]
    e = extend_ranges(cal, rise, path=np.array([1.0, 1.0]))
    s, g = e.densities["f:small"], e.densities["f:large"]
    assert s.low.tolist() == [1.2, 0.9] and s.high.tolist() == [3.0, 1.1]   # hull [1, 3] x [0.9, 1.1]
    assert g.low.tolist() == [1.2, 0.9] and g.high.tolist() == [5.0, 1.1]   # magnitudes 2 and 3
    assert np.array_equal(s.std, cal.densities["f:small"].std)


@pytest.fixture(scope="module")
def lon_isolation():
    from fdikit.systems.car.monitor import isolation_study

    return isolation_study("longitudinal")


#: the one run the calibration does not isolate: its features at 1.5 rad/s sit within about one
#: no-fault standard deviation of the accelerometer hypothesis's during the rise (|set2/w_front_sum|
#: 1.1 against 0.75 +- 0.86), and the narrower accelerometer density takes 0.4 s of it
FRONT_SUM_SMALLEST = ("front_wheel_sum", "1.5")


@pytest.mark.slow
def test_longitudinal_isolation_at_the_calibration_magnitudes(lon_isolation):
    """Every longitudinal fault at every magnitude of MAGNITUDES, on noise the calibration did not
    see (curve, onset 6 s): its own probability >= 0.95 at the end, every other <= 0.05, and no
    other fault announced; the nominal run announces nothing. Before the rise coverage the brake
    actuator at 0.3 and 0.9 MPa was announced as the brake sensor, the engine-speed sensor at
    10 rpm as a front wheel-speed sum and the rear wheel-speed sum at 1.5 as the accelerometer.
    The front wheel-speed sum at 1.5 ends isolated but passes through an accelerometer announcement
    (strict xfail below)."""
    from fdikit.systems.car.monitor import LONGITUDINAL_FAULTS, MAGNITUDES

    r = lon_isolation
    assert r["nominal_wrong"] == [] and r["nominal_max_probability"] < 0.5, r["nominal_max_probability"]
    for name, f in LONGITUDINAL_FAULTS.items():
        assert sorted(float(m) for m in r["runs"][name]) == sorted(MAGNITUDES[f])
    bad = {(n, m): v for n, d in r["runs"].items() for m, v in d.items()
           if not v["isolated"] and (n, m) != FRONT_SUM_SMALLEST}
    assert not bad, bad
    v = r["runs"][FRONT_SUM_SMALLEST[0]][FRONT_SUM_SMALLEST[1]]
    assert v["final_own"] >= 0.95 and v["final_max_other"] <= 0.05, v
    assert {h for _t, h in v["wrong"]} <= {"accelerometer"}, v


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason=(
    "known shortfall: the front wheel-speed sum at 1.5 rad/s is announced as the accelerometer for "
    "0.4 s during its rise before its own announcement (0.8 s); its features are within one no-fault "
    "standard deviation of the accelerometer hypothesis's there"))
def test_front_wheel_sum_smallest_isolated(lon_isolation):
    v = lon_isolation["runs"][FRONT_SUM_SMALLEST[0]][FRONT_SUM_SMALLEST[1]]
    assert v["isolated"], v


def test_warmup_mhsspt_restarts_its_warmup_after_a_gap():
    """resume(n_held) (called by Monitor after held samples) makes the next ``warmup`` samples see
    the no-fault features again; sample numbering (and a checkpoint) keep counting."""
    from fdikit.detect import UniformMeanGaussian
    from fdikit.systems.car.monitor import WarmupMHSSPT

    dens = {"none": UniformMeanGaussian([0], [0], [1]), "bias": UniformMeanGaussian([2], [4], [1])}
    t = WarmupMHSSPT(["r"], dens, p=1e-3, warmup=3)
    t.reset(1)
    for _ in range(3):
        t.step([0.0])
    assert t.step([9.0])[0, 1] > 0.5          # after the warm-up a large feature counts
    t.reset(1)
    for _ in range(5):
        t.step([0.0])
    t.resume(2)
    state = t.get_state()
    assert t.step([9.0])[0, 1] < 0.01         # warm-up again: ignored
    t.set_state(state)                        # the restart survives a checkpoint
    assert t.step([9.0])[0, 1] < 0.01
    assert t._k == 6
