"""Issue 27, item 7: the simulated car's redundant groups (peer checks) and the fault-type stage:
the peer signals in closed form, their design refusing what it cannot fit, a synthetic fault
named and typed, and (slow) faults injected into simulated drives named with the right sensor and
type, with no false announcement on nominal drives."""

import numpy as np
import pytest

from fdikit import Signals
from fdikit.errors import DataError, ModelError
from fdikit.systems.car.model import DEFAULT_PARAMS
from fdikit.systems.car.monitor import CarPeerSignals, design_car_peer_stages

CHANNELS = ["throttle", "brake", "steer", "p_man", "w_engine", "a_x", "w_front_sum", "w_rear_sum",
            "throttle_meas", "brake_meas", "a_y", "yaw_rate", "w_front_diff", "w_rear_diff"]


def _synthetic_drives(runs=2, T=4000, dt=0.01, seed=0):
    """Monitor inputs of a car that weaves and changes speed, made from the relations the peer
    signals invert (with sensor noise): yaw rate r, speed U, a_y = U r, w_*_diff = k r, the steering
    of the single track, the engine through the gear with a slip that follows the manifold pressure."""
    rng = np.random.default_rng(seed)
    p = DEFAULT_PARAMS
    L = p["a"] + p["b"]
    K = p["m"] / L * (p["b"] / (2 * p["C_alpha_f"]) - p["a"] / (2 * p["C_alpha_r"]))
    t = np.arange(T) * dt
    out = np.zeros((runs, T, len(CHANNELS)))
    for i in range(runs):
        ph = rng.uniform(0, 2 * np.pi, 3)
        U = 20 + 2 * np.sin(2 * np.pi * t / 17 + ph[0])
        r = 0.05 * np.sin(2 * np.pi * t / 9 + ph[1]) + 0.02 * np.sin(2 * np.pi * t / 4 + ph[2])
        pm = 40 + 5 * np.sin(2 * np.pi * t / 6 + ph[2])
        ws = 2 * U / p["r_w"]
        v = {"throttle": 8 + 0 * t, "brake": 0 * t, "steer": r * (L + K * U**2) / U, "p_man": pm,
             "w_engine": ws * p["i_gear"] * p["i_final"] / 2 * (1.03 + 0.001 * (pm - 40)), "a_x": 0 * t,
             "w_front_sum": ws, "w_rear_sum": ws, "throttle_meas": 8 + 0 * t, "brake_meas": 0 * t,
             "a_y": U * r, "yaw_rate": r, "w_front_diff": -8.0 * r, "w_rear_diff": -7.0 * r}
        noise = {"w_engine": 1.0, "w_front_sum": 0.1, "w_rear_sum": 0.1, "a_y": 0.05, "yaw_rate": 0.002,
                 "w_front_diff": 0.05, "w_rear_diff": 0.05, "p_man": 0.3}
        for j, c in enumerate(CHANNELS):
            out[i, :, j] = v[c] + noise.get(c, 0.0) * rng.standard_normal(T)
    return Signals(t, out, CHANNELS)


def test_peer_signals_closed_form_batch_equals_streaming_and_round_trip():
    g = CarPeerSignals(-8.0, -7.0)
    sig = _synthetic_drives(runs=2, T=300)
    out = g.run(sig)
    p = DEFAULT_PARAMS
    U = p["r_w"] * sig["w_rear_sum"] / 2
    assert np.allclose(out["sig:lateral_accelerometer"], sig["a_y"] / U)
    assert np.allclose(out["sig:front_wheel_diff"], sig["w_front_diff"] / -8.0)
    assert np.allclose(out["sig:engine_speed"], 2 * sig["w_engine"] / (p["i_gear"] * p["i_final"]))
    assert np.array_equal(out["raw:yaw_rate"], sig["yaw_rate"])
    # the noise-free steering model is the yaw rate itself (the single track's steady turn)
    clean = CarPeerSignals(-8.0, -7.0).run(_synthetic_drives(runs=1, T=300, seed=3))
    assert np.abs(clean["sig:steering"] - clean["sig:yaw_rate"]).max() < 0.01
    g.reset(2)
    u, y = sig.values[:, :, sig.index(g.u_names)], sig.values[:, :, sig.index(g.y_names)]
    stream = np.stack([g.step(u[:, k], y[:, k]) for k in range(sig.n_samples)], axis=1)
    assert np.array_equal(stream, out.values)
    again = CarPeerSignals.from_dict(g.to_dict())
    assert np.array_equal(again.run(sig).values, out.values)
    assert g.settling_time == 0.0       # stateless: the monitor's default warm-up stays the filters'


def test_peer_stages_save_and_load_as_artifacts(tmp_path):
    from fdikit.base.artifacts import load_artifact, save_artifact

    sig = _synthetic_drives(runs=1, seed=1)
    stages = design_car_peer_stages(sig, 0.01)[:3]
    x = stages[0].run(sig)
    for i, st in enumerate(stages):
        save_artifact(tmp_path / f"s{i}", st)
        again = load_artifact(tmp_path / f"s{i}")
        assert type(again) is type(st)
        inp = sig if i == 0 else (x if i == 1 else x.concat_channels(stages[1].run(x)))
        assert np.array_equal(again.run(inp).values, st.run(inp).values)


def test_peer_signals_refuse_bad_coefficients_and_name_the_bad_sample():
    with pytest.raises(ModelError, match="k_f and k_r"):
        CarPeerSignals(0.0, -7.0)
    sig = _synthetic_drives(runs=1, T=50)
    v = sig.values.copy()
    v[0, 7, CHANNELS.index("a_y")] = np.nan
    with pytest.raises(DataError, match="lateral_accelerometer.*sample 7"):
        CarPeerSignals(-8.0, -7.0).run(Signals(sig.t, v, CHANNELS, check=False))


def test_design_refuses_unknown_groups_short_and_straight_drives():
    nom = _synthetic_drives(runs=1, T=2000)
    with pytest.raises(ModelError, match="unknown peer groups"):
        design_car_peer_stages(nom, 0.01, groups=["wheels"])
    with pytest.raises(DataError, match="at least"):
        design_car_peer_stages(Signals(nom.t[:500], nom.values[:, :500], CHANNELS), 0.01)
    v = nom.values.copy()
    v[..., CHANNELS.index("yaw_rate")] = 0.0
    with pytest.raises(DataError, match="never turn"):
        design_car_peer_stages(Signals(nom.t, v, CHANNELS), 0.01)


@pytest.mark.parametrize("channel, member, size", [("yaw_rate", "sig:yaw_rate", 0.01),
                                                   ("w_front_diff", "sig:front_wheel_diff", 0.15),
                                                   ("w_rear_sum", "sig:rear_wheel_sum", 3.0)])
def test_a_synthetic_bias_is_isolated_on_its_member_and_typed_a_bias(channel, member, size):
    """Designed on two synthetic drives, silent on a third; a bias on one sensor from 20 s is
    isolated on that sensor's member alone and typed ``bias``; a sensor frozen from 20 s ``stuck``."""
    from fdikit.faults import Bias, Stuck, apply_faults

    psig, pc, ftc, names = design_car_peer_stages(_synthetic_drives(runs=2, seed=1), 0.01)
    test = _synthetic_drives(runs=1, seed=2)

    def run(sig):
        x = psig.run(sig)
        out = pc.run(x)
        return out, ftc.run(x.concat_channels(out))

    out, ty = run(test)
    assert max(float(out[f"peer:{m}:isolated"].max()) for m in pc.announce) == 0.0
    assert max(float(ty[f"{m}:active"].max()) for m in ftc.members) == 0.0
    out, ty = run(apply_faults(test, [Bias(channel, size, start=20.0)]))
    k = test.t >= 25.0
    assert out[f"peer:{member}:isolated"][0, k].mean() > 0.9
    assert all(out[f"peer:{m}:isolated"][0].max() == 0.0 for m in pc.announce if m != member)
    assert ty[f"{member}:bias"][0, -1] == 1.0
    _out, ty = run(apply_faults(test, [Stuck(channel, start=20.0)]))
    assert ty[f"{member}:stuck"][0, -1] == 1.0
    assert names[f"{member}:stuck"] == member[4:] + ":stuck"


def test_codegen_refuses_the_peer_signals_by_name():
    """The car's generated C covers the paper's fused monitor; the peer stages are opt-in and their
    car-specific generator has no C emitter: code generation refuses it by name (the core PeerCheck
    and FaultTypeClassifier have emitters)."""
    from fdikit.codegen.stages import stage_emitter

    with pytest.raises(DataError, match="stage CarPeerSignals cannot be generated"):
        stage_emitter(CarPeerSignals(-8.0, -7.0), "p0")


# ---------------------------------------------------------------------------------- simulated drives
@pytest.fixture(scope="module")
def simulated():
    """Both calibrated blocks with the peer stages (designed on :func:`nominal_drives`, seed 1001) and
    held-out drives (seed 2002, three runs of each kind, 20 s)."""
    from fdikit.systems.car.driving import simulate_drive
    from fdikit.systems.car.monitor import (
        calibrate_monitor,
        car_signals,
        nominal_drives,
        sensor_noise,
        with_peer_checks,
    )

    nom = nominal_drives(20.0)
    mons = {b: with_peer_checks(calibrate_monitor(b, 20.0), nom) for b in ("longitudinal", "lateral")}
    drives = {k: car_signals(simulate_drive(k, 20.0, duration=20.0, runs=3, seed=2002, dt=2.5e-3,
                                            noise=sensor_noise()))
              for k in ("curve", "speed_change", "straight")}
    return mons, drives


@pytest.mark.slow
def test_no_false_announcement_on_held_out_nominal_drives(simulated):
    mons, drives = simulated
    ev = [(k, b, e.run, round(e.t, 2), e.hypothesis) for k, s in drives.items() for b, m in mons.items()
          for e in m.run(s).events]
    assert ev == []


ONSET = 3.0


def _episodes(mon, sig, component):
    """Per run: the first sensor named by a typed announcement (onset or change) after the onset,
    the final name of ``component``'s episode, and the typed onsets naming another sensor."""
    r = mon.run(sig)
    out = []
    for run in range(sig.runs):
        ons = [e for e in r.events if e.run == run and e.t >= ONSET]
        ch = [e for e in r.changes if e.run == run]
        typed = sorted([(e.t, e.hypothesis) for e in ons + ch if ":" in e.hypothesis])
        final = None
        for _t, h in sorted([(e.t, e.hypothesis) for e in ons + ch]):
            if h.split(":")[0] == component:
                final = h
        wrong = [h for _t, h in typed if h.split(":")[0] != component]
        out.append((typed[0][1].split(":")[0] if typed else None, final, wrong))
    return out


def _faults(kind):
    from fdikit.faults import Bias, Gain, Ramp, Stuck

    mk = {"bias": lambda c, v: Bias(c, v, start=ONSET), "gain": lambda c, v: Gain(c, v, start=ONSET),
          "drift": lambda c, v: Ramp(c, v, start=ONSET), "stuck": lambda c, _v: Stuck(c, start=ONSET)}
    return mk[kind]


#: The faults are applied to the recorded (noisy) measurements, as a sensor's own output: a frozen
#: sensor repeats its last reading exactly (the simulator's Stuck acts before the measurement noise,
#: which would then hide the frozen value). Neither sensor is in the speed or path control loop.
#: (channel, sensor name, block, drive, type, size): the yaw rate and the front wheel-speed difference
#: on the curve (the fault from 3 s, on the straight before it), the front wheel-speed sum on the
#: speed steps (a gain is told from a bias only where the signal moves other than with time)
INJECTED = [(ch, comp, blk, drive, kind, size)
            for ch, comp, blk, drive, sizes in [
                ("yaw_rate", "yaw_rate", "lateral", "curve", {"bias": 0.01, "drift": 0.002, "stuck": None}),
                ("w_front_diff", "front_wheel_diff", "lateral", "curve",
                 {"bias": 0.15, "drift": 0.03, "stuck": None}),
                ("w_front_sum", "front_wheel_sum", "longitudinal", "speed_change",
                 {"bias": 2.5, "gain": 1.03, "drift": 0.3, "stuck": None})]
            for kind, size in sizes.items()]


@pytest.mark.slow
@pytest.mark.parametrize("channel, component, block, drive, kind, size", INJECTED,
                         ids=[f"{c[0]}-{c[4]}" for c in INJECTED])
def test_injected_sensor_fault_named_with_its_sensor_and_type(simulated, channel, component, block, drive,
                                                               kind, size):
    """Measured on six held-out drives (seeds 2002 and 3003): every case named with its sensor and
    its type in 6 of 6 runs; a front wheel-speed sum bias also names the rear sum once in 1 of 6, at
    the speed step down (13.5 s: the rear's peers are the front and the engine, whose mean the faulty
    front moves by half its fault; before the two sums shared one threshold, in 16 of 24 front-sum
    runs of the four types)."""
    from fdikit.faults import apply_faults

    mons, drives = simulated
    sig = apply_faults(drives[drive], [_faults(kind)(channel, size)])
    for first, final, wrong in _episodes(mons[block], sig, component):
        assert first == component and final == f"{component}:{kind}", (first, final, wrong)
        assert len(wrong) <= 1, wrong


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason=(
    "known limit: a yaw-rate gain (x1.3 from 3 s) shows only at the curve entry, where the yaw rate "
    "rises once and then stays constant on the 300 m curve; its residual is a step, typed a bias (6 of 6 "
    "held-out drives, the sensor right in 6 of 6). The simulated drives have no yaw excitation that would "
    "tell a gain from a bias (a gain of the wheel-speed sum on the speed steps is typed a gain, 6 of 6)"))
def test_yaw_gain_on_the_constant_curve_is_typed_a_gain(simulated):
    mons, drives = simulated
    from fdikit.faults import apply_faults

    sig = apply_faults(drives["curve"], [_faults("gain")("yaw_rate", 1.3)])
    res = _episodes(mons["lateral"], sig, "yaw_rate")
    assert all(first == "yaw_rate" for first, _f, _w in res), res
    assert all(final == "yaw_rate:gain" for _first, final, _w in res), res


@pytest.mark.slow
def test_scenarios_with_and_without_the_sensor_stages():
    """On by default where the paper's announcements are unchanged (the longitudinal block: the
    brake-actuator scenario announces exactly as without, probabilities bitwise equal); the lateral
    block's yaw group is opt-in: with it the intermittent front-wheel fault is one episode whose type
    is revised to intermittent, where the paper's monitor announces each burst apart."""
    from fdikit.systems.car.scenarios import SENSOR_STAGES_DEFAULT, run_scenario

    assert SENSOR_STAGES_DEFAULT == {"longitudinal": True, "lateral": False}
    on, off = (run_scenario("brake_actuator_short", sensor_stages=v) for v in (None, False))
    assert on["summary"]["sensor_faults"] == [] and off["summary"]["sensor_faults"] is None
    for k in ("isolated", "detection_delay_s", "false_announcements", "peak_probability"):
        assert on["summary"][k] == off["summary"][k], k
    assert np.array_equal(on["probabilities"].values, off["probabilities"].values)
    a, b = (run_scenario("intermittent_front_wheel", sensor_stages=v) for v in (False, True))
    assert [e.hypothesis for e in a["events"]] == ["front_wheel_diff", "front_wheel_diff"]
    assert [e.hypothesis for e in b["events"]] == ["front_wheel_diff"]
    assert b["summary"]["sensor_faults"][-1]["hypothesis"] == "front_wheel_diff:intermittent"
    assert a["summary"]["windows"] == b["summary"]["windows"]
