"""Checkpoint / restore on the papers' monitors: stopped mid-record, saved to a file, restored into
a freshly built monitor and continued, the outputs equal an uninterrupted run (to 1e-12; in fact
bitwise)."""

import numpy as np

from fdikit import Signals
from fdikit.detect import GLRT, Hold, TimeGated
from fdikit.monitor import Decision, Monitor


def _resume_equals_uninterrupted(build, sig: Signals, cut: int, tmp_path):
    full = build().stream(sig)
    mon = build()
    mon.reset(sig.runs)
    for k in range(cut):
        mon.step(float(sig.t[k]), sig.values[:, k], sig.names)
    mon.save_checkpoint(tmp_path / "ck.npz")
    del mon
    other = build()
    other.load_checkpoint(tmp_path / "ck.npz")
    R, S = [], []
    for k in range(cut, sig.n_samples):
        r, s, _ = other.step(float(sig.t[k]), sig.values[:, k], sig.names)
        R.append(r)
        S.append(s)
    np.testing.assert_allclose(np.stack(R, 1), full.residuals.values[:, cut:], rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.stack(S, 1), full.statistics.values[:, cut:], rtol=0, atol=1e-12)
    return full


def test_abs_monitor(tmp_path):
    from fdikit.systems.abs.plant import Scenario, simulate
    from fdikit.systems.abs.residuals import ABSObserver, ParityR1

    res = simulate(None, Scenario("F2.2", magnitude=-0.25), runs=1, seed=4)
    sig = res.u.concat_channels(res.y)
    dt = float(sig.t[1] - sig.t[0])

    def build():
        r1, obs = ParityR1(dt), ABSObserver(dt)
        g1 = GLRT(["r1"], 0.05, 0.18, W=50)
        g34 = GLRT(["r3", "r4"], [-0.035, -0.033], [8e-3, 5e-3], W=10)
        return Monitor([r1, obs], [g1, g34, Hold(["r1:glrt"], 164.0, Z=40, absolute=False),
                                   TimeGated(["r3:glrt"], 62.0, T=0.5)],
                       Decision(["r1:glrt:alarm", "r3:glrt:gated"]))

    full = _resume_equals_uninterrupted(build, sig, 700, tmp_path)
    assert full.events  # an R_w fault of -25 % is detected: the test ran a real diagnosis


def test_sliding_mode_reconstructor(tmp_path):
    from fdikit.residuals.smo import design_reconstructor, simulate_plant
    from fdikit.systems import aircraft
    from fdikit.systems.aircraft.reconstruction import X0

    h = 1e-4
    rec = design_reconstructor(aircraft.model(), dt=h, hinf_check=False)
    t = np.arange(0, 1.0, h)
    f = aircraft.fault_signal(t + 5.0)  # inside the ramp of the fault
    Y = simulate_plant(aircraft.A_NOMINAL, aircraft.M, aircraft.C, f[:, None], h, x0=X0)
    U = np.zeros((1, t.size, len(rec.u_names)))
    sig = Signals(t, np.concatenate([U, Y.reshape(1, t.size, -1)], axis=2), [*rec.u_names, *rec.y_names])

    def build():
        return Monitor([design_reconstructor(aircraft.model(), dt=h, hinf_check=False)])

    _resume_equals_uninterrupted(build, sig, 4000, tmp_path)
