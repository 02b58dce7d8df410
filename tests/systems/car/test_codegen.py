"""fdikit.systems.car.codegen: the fused passenger-car monitor (filters, parity equations,
features, per-block tabulated MHSSPTs with their warm-up, hold-then-announce) as generated C equals
the Python monitor bitwise (issue 29) on a faulty drive with a NaN sample and a gap (the warm-up
again after it), and checkpoints move C <-> Python."""

from __future__ import annotations

import numpy as np
import pytest

from fdikit.codegen import find_compiler
from fdikit.monitor import Decision, Monitor

from ...codegen.equivalence import assert_equivalent, assert_nan_held, build
from .test_fused import setup  # noqa: F401  (the module fixture: two calibrated blocks, a faulty log)

pytestmark = pytest.mark.skipif(find_compiler() is None, reason="no C compiler (cc, gcc or clang) on PATH")


@pytest.mark.slow   # (the calibrated blocks of test_fused's fixture take ~45 s; the test itself ~6 s)
def test_fused_car_monitor_c_equals_python(setup, tmp_path):  # noqa: F811
    fused, log = setup["fused"], setup["log"]
    dec = Decision([f"A:{f}" for f in fused.faults], 0.5, {f"A:{f}": f for f in fused.faults})
    mon = Monitor([fused], [], dec, on_invalid="hold")
    c64, c32, em = build(mon, tmp_path, "fdk_car", f32=True)
    names = list(mon.input_names)
    x = log.values[0][:, log.index(names)].copy()
    t = log.t.copy()
    x[60, 3] = np.nan
    t[120:] += 4 * fused.dt                      # a gap: the fused monitor's warm-up again
    _out, status, ev = assert_equivalent(mon, c64, em, t, x, min_events=1, batch=False)
    assert (status == 2).sum() > 0
    r32 = c32.run(t, x)
    assert [e["hypothesis"] for e in r32["events"]] == [e[2] for e in ev]
    assert_nan_held(mon, c64, em, log.t, log.values[0][:, log.index(names)], 90)
