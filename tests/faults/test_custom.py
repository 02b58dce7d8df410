"""A new fault shape through the public hook ``Fault.shape(t, p)`` (issue 17), and ``Chirp``."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
import pytest
from scipy.signal import chirp as scipy_chirp

from fdikit.faults import Chirp, Fault, Scenario
from fdikit.model.linear import LinearFaultModel
from fdikit.sim import simulate


@dataclass
class Square(Fault):
    """A user's shape: only the public hook, no private method."""

    amplitude: Any = 1.0
    period: float = 1.0
    per_run_fields: ClassVar[tuple[str, ...]] = ("amplitude",)

    def shape(self, t, p):
        return p["amplitude"] * np.sign(np.sin(2 * np.pi * (t - self.start) / self.period))


def test_custom_shape_needs_only_the_public_hook():
    f = Square("sensor:v", 2.0, period=1.0, start=1.0, end=3.0)
    sig = f.signal([0.5, 1.25, 1.75, 2.25, 3.5], base=10.0)
    np.testing.assert_array_equal(sig, [[10.0, 12.0, 8.0, 12.0, 10.0]])
    # per-run amplitudes reach the hook as arrays
    g = Square("sensor:v", [1.0, 3.0], period=1.0)
    np.testing.assert_array_equal(g.signal([0.25], base=[0.0, 0.0]), [[1.0], [3.0]])


def test_a_fault_without_a_shape_says_what_to_implement():
    @dataclass
    class Nothing(Fault):
        pass

    with pytest.raises(NotImplementedError, match=r"shape\(t, p\)"):
        Nothing("sensor:v").apply(0.0, [0.0])


def test_custom_shape_drives_a_simulation():
    plant = LinearFaultModel([[-1.0]], [[1.0]], [[1.0]], inputs=["u"], outputs=["y"], faults=["actuator:u"])
    sc = Scenario(duration=2.0, dt=0.01, inputs=lambda t: 0.0,
                  faults=[Square("actuator:u", 1.0, period=0.5, start=0.5)])
    res = simulate(plant, sc, runs=1, seed=0)
    y = res.y["y"][0]
    assert np.abs(y[res.y.t < 0.5]).max() == 0.0 and np.abs(y[res.y.t > 0.6]).max() > 0.1


def test_chirp_matches_scipy():
    t = np.linspace(0.0, 4.0, 4001)
    c = Chirp("sensor:v", 1.5, f0=0.2, f1=3.0, sweep_time=4.0, start=0.0)
    ours = c.signal(t)[0]
    # scipy's linear chirp is cos(2 pi (f0 t + (f1 - f0) t^2 / (2 T)) + phi); sin = cos(. - 90 deg)
    ref = 1.5 * scipy_chirp(t, f0=0.2, t1=4.0, f1=3.0, method="linear", phi=-90.0)
    np.testing.assert_allclose(ours[:-1], ref[:-1], atol=1e-9)


def test_chirp_holds_f1_after_the_sweep_and_validates():
    c = Chirp("sensor:v", 1.0, f0=1.0, f1=2.0, sweep_time=1.0, start=0.0)
    t = np.linspace(1.0, 3.0, 2001)
    s = c.signal(t)[0]
    # after the sweep: a 2 Hz sinusoid with the phase reached at the end of the sweep (1.5 cycles)
    np.testing.assert_allclose(s, np.sin(2 * np.pi * (1.5 + 2.0 * (t - 1.0))), atol=1e-9)
    with pytest.raises(Exception, match="sweep_time"):
        Chirp("sensor:v", 1.0, sweep_time=0.0)
