"""fdikit.codegen's sensor-check and scheduled-blend emitters and its emitter registry (issue 29).

Random scheduled filter banks (the scheduling variable an extra input, or a scaled measurement)
into stuck detectors (with and without an expected signal) and peer checks (odd and even peer
counts, a reference), on random logs with faults, NaN and huge samples and a gap (which exercises
the stages' ``resume``): the C gives bitwise the Python streaming outputs, statuses and events; a
NaN sample leaves the state alone; checkpoints move between C and Python. The registry refuses
bad registrations and finds a stage's emitters by the plugin convention; ``subset_monitor`` and
``generate(stop_after=...)`` cut a monitor after a processor.
"""

from __future__ import annotations

import numpy as np
import pytest

from fdikit.codegen import (
    class_path,
    find_compiler,
    register_emitter,
    registered_emitter,
    subset_monitor,
)
from fdikit.codegen.stages import stage_emitter
from fdikit.detect import Hold, PeerCheck, StuckDetector
from fdikit.errors import DataError
from fdikit.monitor import Decision, Monitor
from fdikit.residuals import FilterDesign, ScheduledFilter

from .equivalence import (
    assert_stream_equal,
    c_then_python,
    changed_fields,
    f32_error,
    nan_sample,
    py_stream,
    python_then_c,
    same,
)
from .test_codegen import DT, _build, _stable

pytestmark = pytest.mark.skipif(find_compiler() is None, reason="no C compiler (cc, gcc or clang) on PATH")


def _bank_monitor(seed=0, measured=False):
    """Three random filters (7 residuals) blended in a speed, stuck detectors and peer checks."""
    rng = np.random.default_rng(seed)
    n, q = 3, 7
    ys = ["y0", "y1", "y2"] if measured else ["y0", "y1"]
    designs = [FilterDesign(_stable(rng, n), rng.normal(size=(n, 1)), rng.normal(size=(n, len(ys))),
                            rng.normal(size=(q, n)), rng.normal(size=(q, 1)) * 0.1,
                            rng.normal(size=(q, len(ys))), DT, ["u"], ys, [f"r{i}" for i in range(q)])
               for _ in range(3)]
    gen = ScheduledFilter([5.0, 10.0, 20.0], designs, variable="y2" if measured else "speed",
                          scale=2.0 if measured else 1.0)
    stuck = StuckDetector("r0", "r1", tol=0.6, scale=0.5, threshold=2.0, min_samples=3, warmup=5)
    count = StuckDetector("r2", tol=0.8, scale=4.0, warmup=2)
    # rate channels too (group a: the rate of r5, group b: of r0), their filters in the C state
    peers = PeerCheck({"a": ["r0", "r1", "r2", "r3", "r4"], "b": ["r5", "r6"]},
                      {**{f"r{i}": [0.01 * i, 0.9, 0.2, 0.003 * (i + 1)] for i in range(5)},
                       "r5": [0.0, 1.1, -0.004], "r6": [0.1, 0.8, 0.002]},
                      {f"r{i}": 0.8 + 0.1 * i for i in range(7)}, DT, references={"a": ["r6"]},
                      band_hz={"a": 2.0, "b": 5.0}, announce=["r0", "r2", "r5"], warmup=7,
                      rates={"a": ["r5"], "b": ["r0"]}, rate_hz=3.0)
    hold = Hold(["r0:stuck", "r2:stuck"], 1.0, Z=2, absolute=False)
    alarms = [*hold.output_names, "peer:r0:isolated", "peer:r2:isolated", "peer:r5:isolated"]
    names = {a: a.split(":")[1] + ":" + a.split(":")[-1] for a in alarms}
    dec = Decision(alarms, 0.5, names, clear_after=0.05)
    return Monitor([gen], [stuck, count, peers, hold], dec, on_invalid="hold", dt=DT)


def _log(mon, seed=0, T=1200, gap=True):
    rng = np.random.default_rng(100 + seed)
    names = list(mon.input_names)
    x = rng.normal(scale=0.3, size=(T, len(names)))
    sp = names.index("speed") if "speed" in names else names.index("y2")
    # below, inside and above the scheduling points
    x[:, sp] = 2.0 + 11.0 * (1 + np.sin(np.arange(T) * 0.01)) + 0.1 * rng.normal(size=T)
    x[300:450, names.index("y0")] += 2.0
    x[700:760, names.index("y1")] -= 3.0
    x[500:520, names.index("u")] = 0.0
    x[120, names.index("y0")] = np.nan
    x[121:124, 0] = 1e300
    t = np.arange(T) * DT
    if gap:
        t[900:] += 0.05
    return t, x, names


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("sensor_codegen")
    return {m: (_bank_monitor(measured=m),
                *_build(_bank_monitor(measured=m), tmp / str(m), f"fdk_bank{int(m)}")) for m in (False, True)}


@pytest.mark.parametrize("measured", [False, True])
@pytest.mark.parametrize("seed", [0, 1])
def test_bank_stuck_peer_c_equals_python(built, measured, seed):
    mon, _gen, c64, c32, _em = built[measured]
    t, x, names = _log(mon, seed)
    py_out, py_status, py_ev = py = py_stream(mon, t, x, names)
    assert_stream_equal(c64, t, x, py)
    assert len(py_ev) >= 3 and {1, 2} <= set(py_status.tolist())
    names_out = mon.residual_names + mon.stat_names
    assert py_out[:, names_out.index("r0:stuck")].max() > 0          # the stuck statistic moved
    assert py_out[:, names_out.index("peer:r0:isolated")].max() == 1.0
    assert f32_error(c32, t, x, py_out) < 1e-3


def test_nan_leaves_stage_state_and_checkpoints_cross(built):
    mon, _gen, c64, _c32, em = built[False]
    t, x, names = _log(mon, 2, gap=False)
    cut = 400
    changed = changed_fields(c64.layout, *nan_sample(c64, t, x, cut, names.index("y1")))
    assert changed <= {"k", "held", "held_t", "t_prev"}, changed
    # C -> Python -> C continues bitwise
    full_out, _s, _e = py_stream(mon, t, x, names)
    assert np.array_equal(c_then_python(mon, c64, em, t, x, cut)[1], full_out[cut:])
    res, back = python_then_c(mon, c64, em, t, x, cut)
    assert same(back["processors"], mon.state()["processors"])
    assert np.array_equal(res["out"], full_out[cut:])


def test_registry_refuses_and_finds():
    with pytest.raises(DataError, match="module:qualname"):
        register_emitter("no_colon", object)
    with pytest.raises(DataError, match="StageEmitter"):
        register_emitter("a.b:C", int)
    assert class_path(StuckDetector) == "fdikit.detect.sensor.stuck:StuckDetector"
    assert registered_emitter(StuckDetector("x")).__name__ == "StuckEmitter"
    from fdikit.systems.car.monitor_rav4 import Rav4Preprocessing
    from fdikit.systems.car.monitor_rav4.peers import Rav4PeerSignals

    pre = Rav4Preprocessing(16.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0)
    # found by the plugin convention (fdikit.systems.car.monitor_rav4.codegen)
    em = registered_emitter(Rav4PeerSignals(pre, [1.0, 0.0, 0.0], 1.5, 1.0))
    assert em.__name__ == "Rav4PeerSignalsEmitter"

    class Own(StuckDetector):   # a subclass is not its base: no emitter until one is registered
        pass

    own = Own("x")
    assert registered_emitter(own) is None
    with pytest.raises(DataError, match="Own cannot be generated"):
        stage_emitter(own, "p0")
    register_emitter(class_path(own), registered_emitter(StuckDetector("x")))
    assert stage_emitter(own, "p0").obj is own


def test_subset_monitor_keeps_the_leading_stages():
    mon = _bank_monitor()
    sub = subset_monitor(mon, 2)
    assert [type(p).__name__ for p in sub.processors] == ["StuckDetector", "StuckDetector"]
    assert sub.decision is None and sub.on_invalid == "hold"
    sub = subset_monitor(mon, 3, alarms=["peer:r0:isolated"], names={"peer:r0:isolated": "r0"})
    assert sub.decision.alarm_channels == ["peer:r0:isolated"]
    assert sub.decision.hypothesis("peer:r0:isolated") == "r0"
    assert subset_monitor(mon, 4).decision.alarm_channels == mon.decision.alarm_channels
    with pytest.raises(DataError, match="not produced"):
        subset_monitor(mon, 2, alarms=["peer:r0:isolated"])
    with pytest.raises(DataError, match="n_processors"):
        subset_monitor(mon, 9)
