"""No onset from the filters' start-up transient: ``Monitor(warmup=None)`` warms up at the start
(issue 28, item 5)."""

import numpy as np
import pytest

from fdikit import Signals
from fdikit.faults import Bias
from fdikit.monitor import STATUS_NAMES, Decision, Monitor
from fdikit.residuals import ObserverResidual
from fdikit.systems import two_mass

WARM = STATUS_NAMES.index("warmup")


@pytest.fixture(scope="module")
def arts():
    return two_mass.design({"runs": 100})


def build(arts, **kw):
    dec = Decision(["r:pos1:alarm", "r:pos2:alarm"], level=0.5)
    return Monitor([ObserverResidual(arts["observer"])], [arts["hold"]], dec, **kw)


def mid_operation_log(faults=(), seed=0):
    """A nominal log that starts while the plant moves (the observer starts from rest)."""
    rec = two_mass.record(faults, 1, seed, duration=30.0)
    return Signals(rec.t[:2000], rec.values[:, 1000:3000], rec.names)


def test_default_warmup_announces_nothing_from_the_startup_transient(arts):
    for seed in range(3):
        log = mid_operation_log(seed=seed)
        # without a start-up warm-up the observer's transient is announced at once
        assert any(e.t < 1.0 for e in build(arts, warmup=0.0).run(log).events)
        mon = build(arts)
        a, b = mon.run(log), mon.stream(log)
        assert a.events == [] and b.events == [] and a.cleared == [] and b.cleared == []
        np.testing.assert_array_equal(a.statistics.values, b.statistics.values)
        np.testing.assert_array_equal(a.status, b.status)
        warm = log.t[a.status[0] == WARM]
        assert warm.size and warm.min() == 0.0 and warm.max() <= mon.start_warmup(two_mass.DT) + 1e-9


def test_fault_after_the_startup_is_found_and_quiet_start_ends_early(arts):
    rec = two_mass.record([Bias("sensor:pos2", 0.03, start=6.0)], 1, 5, duration=10.0)  # starts at rest
    mon = build(arts)
    a, b = mon.run(rec), mon.stream(rec)
    assert a.events == b.events and a.events and all(e.t >= 6.0 for e in a.events)
    n_warm = int(np.sum(a.status[0] == WARM))
    # a quiet start ends the warm-up after clear_after (1 s), before the settling time
    assert 0 < n_warm <= round(1.0 / two_mass.DT) + 1 < round(mon.start_warmup(two_mass.DT) / two_mass.DT)
