"""fdikit.codegen: the directional GLRT (anchored and windowed, with and without a nuisance
signature) and ParameterSensitivity (a filter and its twins) as C equal Python bitwise (issue 29),
with a NaN sample held without changing their state and checkpoints C <-> Python."""

from __future__ import annotations

import numpy as np
import pytest

from fdikit.codegen import find_compiler
from fdikit.detect import DirectionalGLRT, Hold
from fdikit.monitor import Decision, Monitor
from fdikit.residuals import FaultDetectionFilter, FilterDesign, ParameterSensitivity

from .equivalence import assert_equivalent, assert_nan_held, build
from .test_codegen import DT, _log, _stable

pytestmark = pytest.mark.skipif(find_compiler() is None, reason="no C compiler (cc, gcc or clang) on PATH")


def _design(rng, scale=1.0):
    n, q = 3, 3
    A = _stable(np.random.default_rng(11), n)
    return FilterDesign(A * scale, rng.normal(size=(n, 1)), rng.normal(size=(n, 2)), rng.normal(size=(q, n)),
                        rng.normal(size=(q, 1)) * 0.1, rng.normal(size=(q, 2)), DT, ["u"], ["y0", "y1"],
                        ["r0", "r1", "r2"])


def _monitor(W, nuisance):
    base = _design(np.random.default_rng(3))
    twins = {"a": FaultDetectionFilter(_design(np.random.default_rng(3), 1.02)),
             "b": FaultDetectionFilter(_design(np.random.default_rng(3), 0.97))}
    gen = ParameterSensitivity(FaultDetectionFilter(base), twins, {"a": 0.02, "b": -0.03},
                               outputs=["r0", "r1"])
    nu = [["sig:r0:b", "sig:r1:b"]] if nuisance else ()
    dg = DirectionalGLRT(["r0", "r1"], ["sig:r0:a", "sig:r1:a"], mu0=[0.01, -0.02], sigma2=[0.05, 0.08], W=W,
                         min_information=1e-3, nuisance=nu, name="da")
    hold = Hold(["da:dglrt"], 8.0, Z=3, absolute=False)
    dec = Decision(hold.output_names, 0.5, {"da:dglrt:alarm": "a"}, clear_after=0.1,
                   size_channels={"da:dglrt:alarm": "da:eta"})
    return Monitor([gen], [dg, hold], dec, on_invalid="hold", dt=DT)


@pytest.mark.parametrize("W,nuisance", [(None, False), (12, False), (None, True), (12, True)])
def test_directional_glrt_and_sensitivity_equal_python(tmp_path, W, nuisance):
    mon = _monitor(W, nuisance)
    c64, c32, em = build(mon, tmp_path, "fdk_dg", f32=True)
    t, x, _names = _log(mon, 0)
    py_out, _st, _ev = assert_equivalent(mon, c64, em, t, x, min_events=1)
    col = [*mon.residual_names, *mon.stat_names].index("da:dglrt")
    assert py_out[:, col].max() > 8.0   # the statistic crosses the hold's threshold
    r32 = c32.run(t, x)
    assert np.isfinite(r32["out"]).all()
    assert_nan_held(mon, c64, em, t, x, 400)
