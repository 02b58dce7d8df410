"""The RAV4 lateral monitor as C (issue 29) on the real minute: the chain up to the peer checks
(``generate(..., stop_after="peer_check")``) and the full chain with the peer CUSUM, the typing peer
check (with the rate terms), the fault-type classifier and its hold (the decision's groups: type
revisions are change events; ``confirm_after``: the unspecific names wait for the peer evidence)
give bitwise the Python monitor's outputs, statuses and events, with injected faults, NaN samples
and a gap; checkpoints cross between C and Python; the float32 variant's error is measured."""

from __future__ import annotations

import numpy as np
import pytest

from fdikit.codegen import (
    CMonitor,
    c_to_py_state,
    compile_shared,
    emit_monitor,
    find_compiler,
    generate,
    py_to_c_state,
)
from fdikit.errors import DataError

from .rav4_example import DATA, rav4_config

pytestmark = [
    pytest.mark.skipif(find_compiler() is None, reason="no C compiler (cc, gcc or clang) on PATH"),
    pytest.mark.skipif(not (DATA / "drive.blf").exists(),
                       reason=f"RAV4 data not found at {DATA} (../shared/data/rav4-highway from the repo)"),
    pytest.mark.slow,   # the design (~15 s) and the compilation of the 240k-coefficient tables
]
#: The fault each run injects (CAN names, DBC units; fdikit.systems.car.monitor_rav4.parse_inject).
FAULTS = ["stuck:STEER_ANGLE_SENSOR@15,YAW_RATE:3.0@40", "gain:WHEEL_SPEED_FL:1.03@20,ACCEL_Y:1.5@45"]


@pytest.fixture(scope="module")
def rav4_c(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("rav4_codegen")
    cfg = rav4_config(tmp)
    res = generate(cfg, tmp / "gen", name="fdk_rav4", stop_after="peer_check")
    libs = {v: CMonitor(compile_shared([tmp / "gen" / f"{n}.c"], tmp / "gen" / f"lib{n}.so"),
                        tmp / "gen" / f"{n}.layout.json")
            for v, n in (("double", "fdk_rav4"), ("float", "fdk_rav4_f32"))}
    return cfg, res, libs


def _log(mon, spec: str, bad: bool):
    from fdikit.systems.car.monitor_rav4 import inject, load_rav4_raw, parse_inject

    sig = inject(load_rav4_raw(DATA), parse_inject(spec), mon.generators[0].pre)
    names = list(mon.input_names)           # (the order the C takes and the tests name the columns)
    t, x = sig.t.copy(), sig.values[0][:, sig.index(names)].copy()
    if bad:  # a NaN yaw rate, a sample of nonsense, then 0.3 s lost (the stages resume)
        x[1500, names.index("yaw_rate_raw")] = np.nan
        x[1501, 0] = 1e300
        t[2200:] += 0.3
    return t, x


def _py(mon, t, x, names):
    mon.reset(1)
    out, status, ev = [], [], []
    for k in range(len(t)):
        r, s, e = mon.step(float(t[k]), x[k][None], names)
        out.append(np.concatenate([r[0], s[0]]))
        status.append(("ok", "cannot_judge", "warmup").index(mon.last_status))
        ev += [(e_.k, e_.kind, e_.hypothesis, e_.episode) for e_ in e]
    return np.array(out), np.array(status), ev


def test_stop_after_refuses_an_unknown_processor(rav4_c, tmp_path):
    """The whole chain generates (PeerCUSUM and the decision's confirm_after have emitters); a stage
    without an emitter (here a subclass of the CUSUM) is refused by name, an unknown stop_after too."""
    import copy

    from fdikit.detect import PeerCUSUM

    cfg, res, _libs = rav4_c
    with pytest.raises(DataError, match="stop_after"):
        generate(cfg, tmp_path / "x", stop_after="nonsense")
    mon = res["monitor"]

    class OwnCUSUM(PeerCUSUM):
        pass

    full = generate(cfg, tmp_path / "all", precisions=("double",))["monitor"]
    i = [type(p).__name__ for p in full.processors].index("PeerCUSUM")
    own = copy.copy(full)
    own.processors = list(full.processors)
    own.processors[i] = OwnCUSUM.from_dict(full.processors[i].to_dict())
    with pytest.raises(DataError, match="OwnCUSUM cannot be generated"):
        emit_monitor(own)
    assert mon.decision is None or mon.decision.confirm_after == 0.0


@pytest.fixture(scope="module")
def rav4_full(rav4_c, tmp_path_factory):
    """The whole chain of the example config (no stop_after), double precision."""
    cfg, _res, _libs = rav4_c
    tmp = tmp_path_factory.mktemp("rav4_full")
    res = generate(cfg, tmp, name="fdk_rav4_full", precisions=("double",))
    return res, CMonitor(compile_shared([tmp / "fdk_rav4_full.c"], tmp / "libfull.so"),
                         tmp / "fdk_rav4_full.layout.json")


@pytest.mark.parametrize("spec", FAULTS)
def test_rav4_full_chain_c_equals_python(rav4_full, spec):
    """With the fault-type classifier: the same outputs bitwise and the same events, changes with
    the name they replace included."""
    res, c64 = rav4_full
    mon = res["monitor"]
    # the detection peer check, its CUSUM, the typing peer check (the wheels' slip term), the typing
    assert res["layout"]["stages"][-5:] == ["PeerCheck", "PeerCUSUM", "PeerCheck", "FaultTypeClassifier",
                                            "Hold"]
    assert mon.decision.confirm_after > 0 and res["layout"]["n_tentative"] > 0
    assert res["seconds"] < 2.0
    t, x = _log(mon, spec, bad=True)
    names = c64.layout["inputs"]
    mon.reset(1)
    out, ev = [], []
    for k in range(len(t)):
        r, s, e = mon.step(float(t[k]), x[k][None], names)
        out.append(np.concatenate([r[0], s[0]]))
        ev += [(e_.k, e_.kind, e_.hypothesis, e_.episode, e_.value, e_.size, e_.previous) for e_ in e]
    c = c64.run(t, x)
    assert np.array_equal(c["out"], np.array(out))
    assert [(e["k"], e["kind"], e["hypothesis"], e["episode"], e["value"], e["size"], e["previous"])
            for e in c["events"]] == ev
    kinds = {e[1] for e in ev}
    # (a type is revised within an episode: change events; since the peer CUSUM and confirm_after
    # joined the chain, on both logs)
    assert kinds == {"onset", "change", "cleared"}


def test_rav4_full_chain_checkpoint_crosses(rav4_full):
    res, c64 = rav4_full
    mon = res["monitor"]
    em = emit_monitor(mon, name="fdk_rav4_full").emitters
    t, x = _log(mon, FAULTS[1], bad=False)
    names = c64.layout["inputs"]
    full = c64.run(t, x)
    cut = 2600                                       # the wheel's gain being typed
    c64.run(t[:cut], x[:cut])
    c_ep = c_to_py_state(c64.layout, c64.checkpoint(), mon, em)["episodes"]
    _py(mon, t[:cut], x[:cut], names)
    for key, v in mon.state()["episodes"].items():  # (confirm: the wait of the unspecific names)
        assert np.array_equal(c_ep[key], v), key
    fresh = CMonitor(c64.lib._name, c64.layout)
    fresh.restore(py_to_c_state(c64.layout, mon.state(), em))
    rest = fresh.run(t[cut:], x[cut:], reset=False)
    assert np.array_equal(rest["out"], full["out"][cut:])
    assert rest["events"] == [e for e in full["events"] if e["k"] >= cut]
    c64.run(t[:cut], x[:cut])
    mon.reset(1)
    mon.restore(c_to_py_state(c64.layout, c64.checkpoint(), mon, em))
    tail = np.array([np.concatenate([r[0], s[0]]) for r, s, _ in
                     (mon.step(float(t[k]), x[k][None], names) for k in range(cut, len(t)))])
    assert np.array_equal(tail, full["out"][cut:])


@pytest.mark.parametrize("spec", FAULTS)
def test_rav4_c_equals_python_on_the_real_minute(rav4_c, spec):
    _cfg, res, libs = rav4_c
    mon, c64 = res["monitor"], libs["double"]
    stages = ["Rav4LateralFilter", "Rav4SensorChannels", "Rav4PeerSignals", "FeatureNorms", "Rav4MHSSPT",
              "Hold", "StuckDetector", "Hold", "PeerCheck"]
    assert res["layout"]["stages"] == stages
    t, x = _log(mon, spec, bad=True)
    names = c64.layout["inputs"]
    py_out, py_status, py_ev = _py(mon, t, x, names)
    c = c64.run(t, x)
    assert np.array_equal(c["status"], py_status) and {1, 2} <= set(py_status.tolist())
    assert np.array_equal(c["out"], py_out)          # bitwise
    assert [(e["k"], e["kind"], e["hypothesis"], e["episode"]) for e in c["events"]] == py_ev
    assert any(e[1] == "onset" for e in py_ev)
    # float32: the error relative to each channel's largest magnitude (measured 4.7e-4), the same events
    c32 = libs["float"].run(t, x)
    scale = np.maximum(np.abs(py_out).max(axis=0), 1e-12)
    assert np.max(np.abs(c32["out"] - py_out) / scale) < 1e-2
    assert [(e["k"], e["kind"], e["hypothesis"], e["episode"]) for e in c32["events"]] == py_ev


def test_rav4_checkpoint_crosses_between_c_and_python(rav4_c):
    _cfg, res, libs = rav4_c
    mon, c64 = res["monitor"], libs["double"]
    t, x = _log(mon, FAULTS[0], bad=False)
    names = c64.layout["inputs"]
    em = emit_monitor(mon, name="fdk_rav4").emitters
    full = c64.run(t, x)
    cut = 2100
    c64.run(t[:cut], x[:cut])
    mon.reset(1)
    mon.restore(c_to_py_state(c64.layout, c64.checkpoint(), mon, em))
    rest = np.array([np.concatenate([r[0], s[0]]) for r, s, _ in
                     (mon.step(float(t[k]), x[k][None], names) for k in range(cut, len(t)))])
    assert np.array_equal(rest, full["out"][cut:])
    _py(mon, t[:cut], x[:cut], names)
    fresh = CMonitor(c64.lib._name, c64.layout)
    fresh.restore(py_to_c_state(c64.layout, mon.state(), em))
    assert np.array_equal(fresh.run(t[cut:], x[cut:], reset=False)["out"], full["out"][cut:])

