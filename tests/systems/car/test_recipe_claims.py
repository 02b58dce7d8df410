"""The passenger-car recipe states its announcement claim (issue 26, item 9's claims table): the
designed monitor's announcements on fault-free drives of its calibration's kinds, with the exact
Poisson interval; a drive with a fault announces."""

import numpy as np
import pytest


@pytest.mark.slow
def test_car_recipe_claim_from_its_nominal_design_drives():
    from fdikit.evaluate import announcement_claim
    from fdikit.faults import Bias
    from fdikit.monitor import Decision, Monitor
    from fdikit.signals import Signals
    from fdikit.systems.car.driving import simulate_drive
    from fdikit.systems.car.monitor import car_signals, sensor_noise
    from fdikit.systems.car.recipe import design, operating_point

    d = design({"calibration_seconds": 8.0})
    (claim,) = d["_report"]["claims"]
    assert claim["kind"] == "decision" and claim["events"] == 0 and claim["target"] is None
    assert claim["hours"] * 3600 == pytest.approx(16.0, abs=0.1)           # two drives of 8 s
    assert claim["interval"][1] == pytest.approx(3.6889 / (claim["hours"]), rel=1e-3)
    assert "seeds 11, 12" in claim["basis"]
    # the same count on a drive with a fault: the claim would see announcements
    car = d["car"]
    res = simulate_drive("straight", 20.0, duration=12.0, faults=[Bias("sensor:a_x", 0.6, start=6.0)], seed=3,
                         dt=2.5e-3, noise=sensor_noise())
    sig = car_signals(res)
    op = operating_point(20.0)
    dev = Signals(sig.t, sig.values - np.array([op.get(n, 0.0) for n in sig.names]), sig.names, check=False)
    chans = [n for n in car.output_names if n.startswith("A:")]
    assert announcement_claim(Monitor([car], [], Decision(chans, 0.5)).run(dev), "fault")["events"] >= 1
