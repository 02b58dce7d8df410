"""fdikit.codegen.arrays: constant C arrays of exact values (issue 29, the car monitor's generation
time). The vectorised hexadecimal literals are the text of ``float.hex`` for every kind of double
(zeros of both signs, subnormals, the extremes, random bit patterns); the C compiler reads them
back bitwise (compiled with the harness flags, ``-std=c99 -pedantic -Werror``); a large table is
written as hexadecimal floats, a short one as decimals; a generation formats a large table once
for both variants and forgets it at the end."""

from __future__ import annotations

import ctypes

import numpy as np
import pytest

from fdikit.codegen import arrays, compile_shared, find_compiler, generate_monitor
from fdikit.codegen.arrays import HEX_FROM, c_array, hex_literals
from fdikit.errors import DataError

SPECIAL = [0.0, -0.0, 1.0, -1.0, 3.0, 0.1, -2.5, 5e-324, -5e-324, 2.2250738585072014e-308,
           2.225073858507201e-308, 1e-310, 1.7976931348623157e308, -1.7976931348623157e308, 1024.0,
           1e10, -1e-10, 1023.5, 2.0 ** -1022, 2.0 ** 1023]


def _values(n=50_000, seed=0):
    """The special values, random bit patterns (all exponents, both signs) and normal draws."""
    rng = np.random.default_rng(seed)
    bits = rng.integers(0, 2 ** 64 - 1, size=n, dtype=np.uint64, endpoint=True)
    r = bits.view(np.float64)
    return np.concatenate([SPECIAL, r[np.isfinite(r)], rng.normal(size=n)])


def _reference(v, per_line):
    items = list(map(float.hex, np.asarray(v, float).tolist()))
    return ",\n".join(", ".join(items[i:i + per_line]) for i in range(0, len(items), per_line))


@pytest.mark.parametrize("per_line", [1, 3, 8])
def test_hex_literals_are_float_hex(per_line):
    v = _values()
    assert hex_literals(v, per_line) == _reference(v, per_line)
    # a count that fills its last line exactly, one value, none
    assert hex_literals(v[:2 * per_line], per_line) == _reference(v[:2 * per_line], per_line)
    assert hex_literals([-0.0], per_line) == "-0x0.0p+0"
    assert hex_literals(np.zeros(0), per_line) == ""


def test_hex_literals_refuse_non_finite_by_index():
    v = np.ones(10)
    v[7] = np.nan
    with pytest.raises(DataError, match="index 7"):
        hex_literals(v)
    with pytest.raises(DataError, match="inf at index 0"):
        hex_literals([np.inf, 1.0])


def test_c_array_large_tables_in_hex_short_ones_in_decimal():
    short = c_array("t", [0.1, -2.0, 3.0])
    assert short == "static const double t[3] = {\n0.1, -2.0, 3.0\n};"
    big = np.linspace(-3.0, 7.0, HEX_FROM)
    text = c_array("big", big)
    assert text.startswith(f"static const double big[{HEX_FROM}] = {{\n-0x1.8000000000000p+1, ")
    assert text.endswith("0x1.c000000000000p+2\n};")
    # non-finite values keep the decimal path (NAN, HUGE_VAL); integers stay integers
    assert "NAN" in c_array("n", np.r_[big, np.nan])
    assert c_array("i", np.arange(3), "int64_t") == "static const int64_t i[3] = {\n0, 1, 2\n};"


@pytest.mark.skipif(find_compiler() is None, reason="no C compiler (cc, gcc or clang) on PATH")
def test_the_compiler_reads_the_literals_back_bitwise(tmp_path):
    v = np.concatenate([_values(20_000, seed=1), np.linspace(-1.0, 1.0, HEX_FROM)])
    src = tmp_path / "tab.c"
    src.write_text(c_array("fdk_tab", v) + "\nconst double *fdk_table(void);\nconst double *fdk_table(void) "
                   "{ return fdk_tab; }\n")
    assert "0x" in src.read_text()
    lib = ctypes.CDLL(str(compile_shared([src], tmp_path / "libtab.so")))
    lib.fdk_table.restype = ctypes.POINTER(ctypes.c_double)
    back = np.ctypeslib.as_array(lib.fdk_table(), shape=(v.size,))
    assert back.tobytes() == v.tobytes()


def test_a_generation_formats_a_large_table_once(tmp_path, monkeypatch):
    """Both variants of a tabulated MHSSPT carry the same table text, formatted once; the text is
    forgotten when the generation ends."""
    from .test_codegen_mhsspt_tab import _tabulated

    calls = []
    real = arrays.hex_literals
    monkeypatch.setattr(arrays, "hex_literals", lambda v, *a: calls.append(len(v)) or real(v, *a))
    mon = _tabulated("cubic", 1 / 16)
    res = generate_monitor(mon, tmp_path, name="fdk_tab")
    assert len(calls) == 1 and calls[0] >= HEX_FROM
    texts = [(tmp_path / f).read_text() for f in ("fdk_tab.c", "fdk_tab_f32.c")]
    tabs = [t[t.index("static const double fdk_p1_coef"):].split("};")[0] for t in texts]
    assert tabs[0] == tabs[1] and "0x1." in tabs[0]
    assert arrays._hex_body.cache_info().currsize == 0
    generate_monitor(mon, tmp_path, name="fdk_tab")
    assert len(calls) == 2 and res["code_bytes"]["double"] > 0
