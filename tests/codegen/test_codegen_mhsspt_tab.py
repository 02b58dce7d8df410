"""fdikit.codegen: the MHSSPT with tabulated densities (linear and cubic tables) as C equals the
Python stage (issue 29): bitwise on random logs with faults, NaN, huge values and a gap, a NaN
feature sample held without changing its state, checkpoints C <-> Python continue bitwise."""

from __future__ import annotations

import numpy as np
import pytest

from fdikit.codegen import emit_monitor, find_compiler
from fdikit.detect import MHSSPT
from fdikit.monitor import Decision, Monitor

from .equivalence import assert_equivalent, assert_nan_held, build
from .test_codegen import _log, _mhsspt_monitor

pytestmark = pytest.mark.skipif(find_compiler() is None, reason="no C compiler (cc, gcc or clang) on PATH")


def _tabulated(interpolation, tabulate, q=0.01):
    base = _mhsspt_monitor(q=q)
    feats, mh = base.processors
    tab = MHSSPT(mh.input_names, dict(zip(mh.hypotheses, mh.densities)), p=1e-3, q=q,
                 groups={"ab": ["fa", "fb"]}, tabulate=tabulate, interpolation=interpolation)
    return Monitor(base.generators, [feats, tab], Decision(tab.output_names[1:4], 0.9, clear_after=0.1),
                   on_invalid="hold")


@pytest.mark.parametrize("interpolation,tabulate", [("linear", 0.125), ("cubic", 1 / 16)])
@pytest.mark.parametrize("q", [0.0, 0.01])
def test_tabulated_mhsspt_equals_python(tmp_path, interpolation, tabulate, q):
    mon = _tabulated(interpolation, tabulate, q)
    c64, c32, em = build(mon, tmp_path, "fdk_tab", f32=True)
    assert "fdk_p1_" + ("coef" if interpolation == "cubic" else "tab") in (tmp_path / "fdk_tab.c").read_text()
    for seed in (0, 1):
        t, x, _names = _log(mon, seed)
        # features beyond the table's grid too: the exact density outside it
        x[1300:1310, 1] += 40.0
        py_out, _st, _ev = assert_equivalent(mon, c64, em, t, x, min_events=2)
        r32 = c32.run(t, x)
        assert np.max(np.abs(r32["out"] - py_out)) < 1e-3
    assert_nan_held(mon, c64, em, t, x, 400)


def test_tabulated_table_is_code_not_state(tmp_path):
    """The tables are constant data: the state is the exact MHSSPT's (log posteriors and k)."""
    lin, exact = _tabulated("linear", 1 / 32), _mhsspt_monitor()
    a = emit_monitor(lin).layout["fields"]
    b = emit_monitor(exact).layout["fields"]
    assert a == b
    assert "static const double fdk_p1_tab" in emit_monitor(lin).source
