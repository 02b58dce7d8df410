"""fdikit.codegen's PeerCUSUM emitter (issue 29): a scheduled filter bank into a peer check and a
two-sided CUSUM on its residuals (groups, a member compared but not announced, a passthrough
member, a warm-up), on random logs with shifts, NaN and huge samples and a gap (the CUSUM starts
again on ``resume``): the C gives bitwise the Python streaming outputs, statuses and events; a NaN
sample is refused without changing the state; checkpoints move between C and Python.
"""

from __future__ import annotations

import numpy as np
import pytest

from fdikit.codegen import find_compiler
from fdikit.detect import PeerCUSUM
from fdikit.monitor import Decision, Monitor

from .equivalence import (
    assert_stream_equal,
    c_events,
    c_then_python,
    changed_fields,
    f32_error,
    field,
    nan_sample,
    py_stream,
    python_then_c,
    same,
)
from .test_codegen import DT, _build
from .test_sensor_codegen import _bank_monitor, _log

pytestmark = pytest.mark.skipif(find_compiler() is None, reason="no C compiler (cc, gcc or clang) on PATH")


def _cusum_monitor(seed=0, warmup=4, transfer=False):
    """The sensor bank's peer check, then a PeerCUSUM (r1, r3, r6 compared only, r2 passed through;
    with ``transfer`` the peer-only transfer rule between them and the announced r0, r5)."""
    base = _bank_monitor(seed)
    gen, peers = base.generators[0], base.processors[2]
    rng = np.random.default_rng(50 + seed)
    members = ["r0", "r1", "r3", "r5", "r6"]
    cus = PeerCUSUM({"a": ["r0", "r1", "r3"], "b": ["r5", "r6"]},
                    {m: 0.05 * rng.normal() for m in members}, {m: 0.1 + 0.1 * rng.random() for m in members},
                    {m: 2.0 + rng.random() for m in members}, warmup=warmup, announce=["r0", "r5"],
                    passthrough=["r2"],
                    transfer={"r0": {"r1": 1.3, "r3": 0.7}, "r1": {"r0": 0.4}, "r3": {"r0": 0.2},
                              "r5": {"r6": 1.1 + rng.random()}, "r6": {"r5": 0.3}} if transfer else None)
    alarms = ["cusum:r0:isolated", "cusum:r2:isolated", "cusum:r5:isolated"]
    dec = Decision(alarms, 0.5, {a: a.split(":")[1] for a in alarms}, clear_after=0.05,
                   size_channels={"r0": "cusum:r0:stat"})
    return Monitor([gen], [peers, cus], dec, on_invalid="hold", dt=DT)


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("peer_cusum_codegen")
    out = {w: (_cusum_monitor(warmup=w), *_build(_cusum_monitor(warmup=w), tmp / str(w), f"fdk_cus{w}"))
           for w in (0, 4)}
    out["transfer"] = (_cusum_monitor(transfer=True),
                       *_build(_cusum_monitor(transfer=True), tmp / "transfer", "fdk_cust"))
    return out


@pytest.mark.parametrize("warmup", [0, 4])
@pytest.mark.parametrize("seed", [0, 1])
def test_peer_cusum_c_equals_python(built, warmup, seed):
    mon, _gen, c64, c32, _em = built[warmup]
    t, x, names = _log(mon, seed)
    py_out, py_status, py_ev = py = py_stream(mon, t, x, names)
    assert_stream_equal(c64, t, x, py)
    cols = mon.residual_names + mon.stat_names
    assert py_out[:, cols.index("cusum:r0")].max() > 1.0          # the CUSUM isolates
    assert py_out[:, cols.index("cusum:r5:isolated")].max() == 1.0
    assert len(py_ev) >= 2 and {1, 2} <= set(py_status.tolist())
    assert f32_error(c32, t, x, py_out) < 1e-3


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_peer_cusum_transfer_rule_c_equals_python(built, seed):
    mon, _gen, c64, c32, _em = built["transfer"]
    t, x, names = _log(mon, seed)
    py = py_stream(mon, t, x, names)
    assert_stream_equal(c64, t, x, py)
    assert f32_error(c32, t, x, py[0]) < 1e-3
    # the rule changes the isolation somewhere (else this test would not exercise it)
    plain, _s, _e = py_stream(built[4][0], t, x, names)
    cols = mon.residual_names + mon.stat_names
    iso = [cols.index(f"cusum:{m}:isolated") for m in ("r0", "r5")]
    assert (py[0][:, iso] > plain[:, iso]).any()


def test_peer_cusum_nan_refused_and_checkpoints_cross(built):
    mon, _gen, c64, _c32, em = built[4]
    t, x, names = _log(mon, 2, gap=False)
    cut = 400
    changed = changed_fields(c64.layout, *nan_sample(c64, t, x, cut, names.index("y0")))
    assert changed <= {"k", "held", "held_t", "t_prev"}, changed
    full_out, _s, full_ev = py_stream(mon, t, x, names)
    # C -> Python continues bitwise
    ck, rest = c_then_python(mon, c64, em, t, x, cut)
    assert np.any(field(c64.layout, ck, "p1_up") != 0)               # the CUSUM state crosses
    assert np.array_equal(rest, full_out[cut:])
    # Python -> C continues bitwise
    res, back = python_then_c(mon, c64, em, t, x, cut)
    assert same(back["processors"], mon.state()["processors"])
    assert np.array_equal(res["out"], full_out[cut:])
    assert c_events(res) == [e for e in full_ev if e[0] >= cut]
