"""fdikit.systems.abs.codegen: the ABS monitor (r1, the nonlinear observer, the paper's five GLRT
tests and the D-matrix diagnosis) as generated C equals the Python monitor (issue 29) on
simulated braking runs with faults: the same statuses and events, the observer's residuals and
the diagnosis bitwise, r1 within 1e-12 of its scale (its spline derivative is a BLAS dot product
in numpy); a NaN sample held without changing any stage's state; checkpoints C <-> Python."""

from __future__ import annotations

import numpy as np
import pytest

from fdikit.codegen import find_compiler
from fdikit.detect import GLRT, Hold, TimeGated
from fdikit.isolate import DMatrix, DMatrixDecision
from fdikit.monitor import Decision, Monitor
from fdikit.systems.abs.campaign import paper_tests, residual_generators
from fdikit.systems.abs.plant import Scenario, simulate

from ...codegen.equivalence import build, c_events, py_stream

pytestmark = pytest.mark.skipif(find_compiler() is None, reason="no C compiler (cc, gcc or clang) on PATH")

DT = 0.01


def _run(fault, seed, t_end=5.0):
    res = simulate(None, Scenario(fault=fault, t_end=t_end), runs=1, seed=seed)
    return res.y.concat_channels(res.u)


def _monitor():
    """The paper's tests with mu0, sigma^2 from one nominal run and thresholds 1.3 times its largest
    statistic (no Monte Carlo design), a D-matrix of the fault classes, a size channel."""
    specs = paper_tests()
    r1, obs = residual_generators(specs, DT)
    nominal = _run("F0", 0, 12.5)
    res = np.concatenate([r1.run(nominal).values[0], obs.run(nominal).values[0]], axis=1)
    procs, alarms = [], []
    for j, s in enumerate(specs):
        col = ["r1", "r3", "r4"].index(s.residual)
        if s.gate is None:
            g = GLRT([s.residual], res[:, col].mean(), res[:, col].var(), s.W)
            nom = g.run(nominal.__class__(nominal.t, res[None, :, col:col + 1], [s.residual])).values[0, :, 0]
            procs += [g, Hold([f"{s.residual}:glrt"], 1.3 * nom.max(), s.Z, absolute=False)]
            alarms.append(f"{s.residual}:glrt:alarm")
        else:
            procs.append(TimeGated([f"{s.residual}:glrt:alarm"], 0.5, s.gate))
            alarms.append(f"{s.residual}:glrt:alarm:gated")
        assert j < 5
    dm = DMatrix(["F0", "F1", "F2", "F3", "F5"], [s.name for s in specs],
                 [[0, 0, 0, 0, 0], [1, 1, 1, 0, 0], [1, 1, 1, 1, 1], [0, 1, 0, 1, 0], [1, 0, 1, 0, 1]],
                 pd=[[0.0] * 5, [0.8, 0.9, 0.9, 0.0, 0.0], [0.9, 0.9, 0.9, 0.7, 0.7],
                     [0.0, 0.8, 0.0, 0.8, 0.0], [0.7, 0.0, 0.9, 0.0, 0.6]], pf=0.02)
    diag = DMatrixDecision(dm, alarms, settle=30, clear=200, sizes={"F2": "r1:glrt"})
    dec = Decision(diag.fault_channels, 0.5, diag.announce, size_channels=diag.size_channels)
    return Monitor([r1, obs], [*procs, diag], dec, on_invalid="hold")


@pytest.fixture(scope="module")
def abs_c(tmp_path_factory):
    mon = _monitor()
    c64, c32, em = build(mon, tmp_path_factory.mktemp("abs"), "fdk_abs", f32=True)
    return mon, c64, c32, em


def _compare(mon, c64, sig):
    names = list(mon.input_names)
    x = sig.values[0][:, sig.index(names)]
    py_out, py_status, py_ev = py_stream(mon, sig.t, x, names)
    res = c64.run(sig.t, x)
    assert np.array_equal(res["status"], py_status)
    scale = np.maximum(np.abs(py_out).max(axis=0), 1e-300)
    err = np.abs(res["out"] - py_out) / scale
    r1_cols = [i for i, n in enumerate(mon.residual_names + mon.stat_names) if n.startswith("r1")]
    others = [i for i in range(py_out.shape[1]) if i not in r1_cols]
    assert np.array_equal(res["out"][:, others], py_out[:, others])
    assert err.max() < 1e-12, err.max(axis=0)
    assert [e[:4] for e in c_events(res)] == [e[:4] for e in py_ev]
    np.testing.assert_allclose([e[4] for e in c_events(res)], [e[4] for e in py_ev], rtol=1e-12)
    return x, py_out, py_ev


@pytest.mark.parametrize("fault,seed", [("F0", 3), ("F1.2", 4), ("F2.2", 5), ("F3", 6)])
def test_abs_monitor_c_equals_python(abs_c, fault, seed):
    mon, c64, c32, _em = abs_c
    sig = _run(fault, seed)
    x, _py_out, py_ev = _compare(mon, c64, sig)
    if fault != "F0":
        assert any(e[1] == "onset" for e in py_ev), fault
    r32 = c32.run(sig.t, x)
    assert [e[2] for e in c_events(r32)] == [e[2] for e in py_ev]   # float32: the same diagnoses


def test_abs_monitor_nan_gap_and_checkpoints(abs_c):
    from fdikit.codegen import CMonitor, c_to_py_state, py_to_c_state

    from ...codegen.equivalence import assert_nan_held

    mon, c64, _c32, em = abs_c
    sig = _run("F2.2", 8)
    names = list(mon.input_names)
    x = sig.values[0][:, sig.index(names)].copy()
    t = sig.t.copy()
    x[150, 1] = np.nan
    t[300:] += 0.05                                            # a gap
    py_out, py_status, py_ev = py_stream(mon, t, x, names)
    res = c64.run(t, x)
    assert np.array_equal(res["status"], py_status)
    assert [e[:4] for e in c_events(res)] == [e[:4] for e in py_ev] and py_ev
    for cut in (120, 330):
        c64.run(t[:cut], x[:cut])
        mon.reset(1)
        mon.restore(c_to_py_state(c64.layout, c64.checkpoint(), mon, em))
        rest = np.array([np.concatenate([r[0], s[0]]) for r, s, _ in
                         (mon.step(float(t[k]), x[k][None], names) for k in range(cut, len(t)))])
        np.testing.assert_allclose(rest, py_out[cut:], rtol=0, atol=1e-12 * np.abs(py_out).max())
        py_stream(mon, t[:cut], x[:cut], names)
        fresh = CMonitor(c64.lib._name, c64.layout)
        fresh.restore(py_to_c_state(c64.layout, mon.state(), em))
        r2 = fresh.run(t[cut:], x[cut:], reset=False)
        assert np.array_equal(r2["status"], py_status[cut:])
        assert [e[:4] for e in c_events(r2)] == [e[:4] for e in py_ev if e[0] >= cut]
    clean = sig.values[0][:, sig.index(names)]
    assert_nan_held(mon, c64, em, sig.t, clean, 250, exact=False)   # (r1's sums: to rounding)


def test_observer_one_run_streaming_equals_batch():
    """The one-run streaming kernel (no thread launch per sample, ~10x faster on a loaded machine)
    gives the batch kernel's numbers bitwise."""
    from fdikit.systems.abs.residuals import ABSObserver

    sig = _run("F2.2", 11, 3.0)
    g = ABSObserver(DT)
    b = g.run(sig).values
    g.reset(1)
    u, y = g._inputs(sig)
    s = np.stack([g.step(u[:, k], y[:, k]) for k in range(sig.n_samples)], axis=1)
    np.testing.assert_array_equal(s, b)
