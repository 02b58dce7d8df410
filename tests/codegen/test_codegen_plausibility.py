"""fdikit.codegen: the plausibility rules (range, rate, spike with windows of two lengths) and the
gap / warm-up policy as C equal the Python monitor (issue 29): on random logs with injected
artefacts (spikes, out-of-range values, jumps, NaN, a gap) the same samples are held, the same
events announced and the statistics are bitwise equal; a NaN sample is held without changing any
stage's state; checkpoints (with the plausibility state) move C <-> Python and continue bitwise."""

from __future__ import annotations

import numpy as np
import pytest

from fdikit.codegen import emit_monitor, find_compiler
from fdikit.errors import DataError
from fdikit.monitor.plausibility import Plausibility

from .equivalence import assert_equivalent, assert_nan_held, build, py_stream
from .test_codegen import _fdf_monitor, _log, _mhsspt_monitor

pytestmark = pytest.mark.skipif(find_compiler() is None, reason="no C compiler (cc, gcc or clang) on PATH")

RULES = {"u": Plausibility(spike=6.0, window=20), "y0": Plausibility(min=-3.0, max=3.2),
         "y1": Plausibility(max_rate=120.0, spike=8.0, window=10)}


def _artefacts(t, x, seed):
    """Spikes, out-of-range values and fast jumps at random places, on top of _log's NaN and gap."""
    rng = np.random.default_rng(100 + seed)
    x = x.copy()
    for k in rng.choice(np.arange(60, len(t) - 5), 25, replace=False):
        x[k, 0] += rng.choice([-1, 1]) * rng.uniform(2.0, 6.0)          # spikes on u
    for k in rng.choice(np.arange(60, len(t) - 5), 8, replace=False):
        x[k, 1] = rng.choice([-5.0, 5.0])                                # out of range on y0
    for k in rng.choice(np.arange(60, len(t) - 5), 10, replace=False):
        x[k:k + 2, 2] += rng.uniform(2.0, 4.0)                          # jumps on y1 (two samples)
    x[700:705, 0] = 0.5                                                  # a flat stretch (MAD 0)
    return x


@pytest.mark.parametrize("which", ["fdf", "mhsspt"])
@pytest.mark.parametrize("seed", [0, 1])
def test_plausibility_equals_python(tmp_path, which, seed):
    mon = (_fdf_monitor if which == "fdf" else _mhsspt_monitor)(plausibility=RULES)
    c64, c32, em = build(mon, tmp_path, f"fdk_pl_{which}", f32=True)
    t, x, _names = _log(mon, seed)
    x = _artefacts(t, x, seed)
    _out, status, _ev = assert_equivalent(mon, c64, em, t, x, min_events=1)
    # the rules fired: more samples held than the NaN / huge ones of the log
    held = int((status == 1).sum())
    assert held > 30, held
    r32 = c32.run(t, x)
    assert np.array_equal(r32["status"], status)   # plausibility is judged in double in both variants


def test_each_rule_holds_samples():
    """Each rule alone holds samples the others do not (every piece of the C is exercised)."""
    base = _fdf_monitor()
    t, x, names = _log(base, 0)
    x = _artefacts(t, x, 0)
    n0 = (py_stream(base, t, x, names)[1] == 1).sum()
    for ch, rule in RULES.items():
        _o, st, _e = py_stream(_fdf_monitor(plausibility={ch: rule}), t, x, names)
        assert (st == 1).sum() > n0, ch


def test_plausibility_nan_held_and_raise_mode(tmp_path):
    mon = _fdf_monitor(plausibility=RULES)
    c64, _c32, em = build(mon, tmp_path, "fdk_pl_nan")
    t, x, _names = _log(mon, 4, gap=False)
    x[120:124], x[650] = 0.1, 0.1                  # (no NaN or huge values: raise mode below)
    assert_nan_held(mon, c64, em, t, x, 400)
    strict = _fdf_monitor(plausibility={"y0": RULES["y0"]})
    strict.on_invalid = "raise"
    cs, _c, _e = build(strict, tmp_path / "strict", "fdk_pl_strict")
    cs.run(t[:300], x[:300])
    before = cs.checkpoint()
    bad = x[300].copy()
    bad[1] = 4.0                                   # above y0's max
    assert cs.step(t[300], bad)[0] == -2          # FDK_ERR_VALUE, as Python raises
    assert np.array_equal(cs.checkpoint(), before)
    py_stream(strict, t[:300], x[:300], list(strict.input_names))
    with pytest.raises(DataError, match="above max"):
        strict.step(float(t[300]), bad[None], list(strict.input_names))


def test_plausibility_without_validation_refused():
    mon = _fdf_monitor(plausibility=RULES)
    mon.validate = False
    with pytest.raises(DataError, match="plausibility cannot be generated with validate=False"):
        emit_monitor(mon)


def test_inf_held_without_max_abs(tmp_path):
    """With max_abs=None an inf sample is still held (Python's non-finite rule), in C too (it
    once passed into the filters and stopped the monitor with FDK_ERR_STAT)."""
    mon = _fdf_monitor(max_abs=None)
    c64, _c32, em = build(mon, tmp_path, "fdk_inf")
    t, x, _names = _log(mon, 0, gap=False)
    x[121:124, 0], x[650, 0] = 0.1, 0.1            # (1e300 would overflow the filters without max_abs)
    x[500, 1] = np.inf
    x[900, 0] = -np.inf
    _out, status, _ev = assert_equivalent(mon, c64, em, t, x, batch=False)
    assert status[500] == 1 and status[900] == 1
