"""fdikit.codegen.stages' shared pieces of generated C: the refusal of non-finite stage inputs
(``refuse_nonfinite``, one branch after or-ing every element's test) returns ``FDK_ERR_STAT`` for a
NaN or an infinity at any position, before any state change, and nothing for finite inputs,
the largest and the subnormal ones included."""

from __future__ import annotations

import ctypes

import numpy as np
import pytest

from fdikit.codegen import compile_shared, find_compiler
from fdikit.codegen.stages import refuse_nonfinite

pytestmark = pytest.mark.skipif(find_compiler() is None, reason="no C compiler (cc, gcc or clang) on PATH")

N = 7


@pytest.fixture(scope="module")
def lib(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("stages")
    src = tmp / "refuse.c"
    src.write_text("\n".join([
        "#include <math.h>", "#include <stdint.h>", "typedef double fdk_real;",
        "#define FDK_FINITE(x) (isfinite(x))", "#define FDK_ERR_STAT (-3)",
        "int refuse(const double *px, int64_t *state, int use_isfinite)", "{", "    int i;",
        "    int64_t j;",
        "    if (use_isfinite) {", refuse_nonfinite("px", N, "j", "isfinite"), "    } else {",
        refuse_nonfinite("px", N), "    }", "    (void)i; (void)j;",
        "    state[0] += 1;   /* the state changes only after the refusal */", "    return 0;", "}", ""]))
    so = compile_shared([src], tmp / "librefuse.so")
    f = ctypes.CDLL(str(so)).refuse
    f.restype = ctypes.c_int
    f.argtypes = [ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_int64), ctypes.c_int]
    return f


@pytest.mark.parametrize("use_isfinite", [0, 1])
def test_nonfinite_refused_at_every_position(lib, use_isfinite):
    state = (ctypes.c_int64 * 1)(0)
    finite = np.array([0.0, -0.0, 1.7976931348623157e308, -1.7976931348623157e308, 5e-324, 1.0, -3.5])
    buf = (ctypes.c_double * N)(*finite)
    assert lib(buf, state, use_isfinite) == 0 and state[0] == 1
    for bad in (np.nan, np.inf, -np.inf):
        for pos in range(N):
            x = finite.copy()
            x[pos] = bad
            buf = (ctypes.c_double * N)(*x)
            assert lib(buf, state, use_isfinite) == -3, (bad, pos)
            assert state[0] == 1
