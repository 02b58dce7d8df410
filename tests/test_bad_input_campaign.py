"""The bad-input campaign (issue 16, item 7): >= 400 cases, each ending in a clear error or in
sound data -- never a traceback, never a silent wrong output, never a NaN or inf in an output.

Grown from ``test_bad_input_monitor.py`` (monitor-level corruption of a real record) and
``test_io_bad_input.py`` (loader corruption of the real RAV4 log), in six classes:

* ``ARTEFACTS`` -- what real logs hold, fed to the three CSV paths (``read_csv`` on the file's
  stamps, ``read_csv`` gridded, the table reader of ``read_log`` gridded): gaps, NaN blocks,
  spikes of 1e300, inf, negative / zero / duplicate / backwards timestamps, epoch and ns
  timestamps, jitter, truncated files, wrong delimiters, a byte-order mark, empty and
  header-only files, text cells, duplicate columns, huge values, ...;
* ``MONITOR`` -- the same artefacts as samples into a running monitor (two-mass example);
* ``CLI`` -- ``fdikit`` commands in-process (:func:`fdikit.cli.main`): missing and unwritable
  output folders, missing config or log, bad flags, bad logs;
* ``CONFIG`` -- config semantics: unknown keys, wrong types, out-of-range values, duplicate
  sources, unknown channels;
* ``ARTIFACTS`` -- missing, corrupt, mismatched, edited or too-new design artifacts;
* ``API`` -- misuse of the Python API: step before reset, wrong shapes, NaN into components, a
  ``Hold`` threshold count that differs from its channel count, bad arguments.

A case passes when the call raises :class:`~fdikit.errors.DataError` (or
:class:`~fdikit.errors.ConditionError`) whose message names the problem (a pattern), or a CLI
exits with a non-zero code and a message naming it (no ``Traceback``), or returns data that
passes the checks of its case. Hypothesis fuzzes the CSV reader, the candump parser and reader,
the BLF reader (files written by python-can from random frames, and corrupted bytes) and follow
mode (CSV lines into ``fdikit monitor --follow``; candump lines through the FrameGridder into
``Monitor.step``).

A case that still fails is marked with :func:`awaits` (a strict xfail naming what it waits for),
so that it turns red the day it passes and its mark must go.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import os
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fdikit.errors import ConditionError, DataError

# asammdf / pyarrow objects that fail in __del__ after raising are not ours
pytestmark = pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning")

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "two-mass" / "monitor.toml"
FUZZ = settings(
    max_examples=25,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)


def awaits(who: str, what: str):
    return pytest.mark.xfail(strict=True, reason=f"awaits {who}: {what}")


def expect_error(call, pattern: str, types=(DataError, ConditionError)):
    """The call raises one of ``types`` with a message matching ``pattern`` (case-insensitive)."""
    with pytest.raises(types) as info:
        call()
    msg = str(info.value)
    assert len(msg) >= 12, msg
    assert re.search(pattern, msg, re.IGNORECASE | re.DOTALL), f"{msg!r} does not match {pattern!r}"
    return msg


def check_log(s):
    """A loaded log is sound: finite strictly increasing time, valid exactly where finite."""
    from fdikit.io import LogSignals

    assert isinstance(s, LogSignals)
    assert s.values.shape == (1, s.t.size, len(s.names))
    assert np.all(np.isfinite(s.t)) and np.all(np.diff(s.t) > 0)
    assert np.array_equal(s.valid, np.isfinite(s.values)), "NaN outside a flagged sample"
    assert math.isfinite(s.t0)
    return s


# =====================================================================================
# 1. real-log artefacts through the CSV readers
# =====================================================================================
N = 600
DT = 0.01
_rng = np.random.default_rng(7)
BASE_X = np.round(np.sin(np.arange(N) * 0.05), 9)
BASE_Y = np.round(np.arange(N) * 0.001, 9)
BASE_Z = np.round(_rng.normal(0, 1, N), 9)


def base_rows() -> list[list[str]]:
    return [
        [f"{k * DT:.2f}", repr(float(BASE_X[k])), repr(float(BASE_Y[k])), repr(float(BASE_Z[k]))]
        for k in range(N)
    ]


def to_text(rows, header=("t", "x", "y", "z"), sep=",", eol="\n") -> str:
    return eol.join([sep.join(header)] + [sep.join(r) for r in rows]) + eol


def rows_where(rows, lo, hi):
    return [k for k, r in enumerate(rows) if lo <= float(r[0]) < hi]


def a_gap(lo, hi):
    def make():
        rows = base_rows()
        drop = set(rows_where(rows, lo, hi))
        return to_text([r for k, r in enumerate(rows) if k not in drop])

    return make


def a_cells(lo, hi, col, text):
    def make():
        rows = base_rows()
        for k in rows_where(rows, lo, hi):
            rows[k][col] = text
        return to_text(rows)

    return make


def a_time(fn, fmt="{:.6f}"):
    def make():
        rows = base_rows()
        for k, r in enumerate(rows):
            r[0] = fn(k) if isinstance(fn(k), str) else fmt.format(fn(k))
        return to_text(rows)

    return make


def a_epoch(unit):
    def stamp(k):
        ns = 1_700_000_000_000_000_000 + k * 10_000_000
        return {
            "ns": str(ns),
            "us": str(ns // 1000),
            "ms": str(ns // 1_000_000),
            "s": f"{ns // 10**9}.{ns % 10**9:09d}",
        }[unit]

    return a_time(stamp)


def a_truncate(frac):
    def make():
        text = to_text(base_rows())
        lines = text.splitlines(keepends=True)
        k = max(2, int(len(lines) * frac))
        cut = lines[k].index(",") + 3  # inside the second field: the line lost fields
        return "".join(lines[:k]) + lines[k][:cut]

    return make


def a_text(text):
    return lambda: text


def a_rows(fn):
    def make():
        rows = base_rows()
        fn(rows)
        return to_text(rows)

    return make


def _dup_row(rows):
    rows.insert(200, list(rows[199]))


def _dup_time(rows):
    rows[200][0] = rows[199][0]


def _back(rows):
    rows[300][0], rows[301][0] = rows[301][0], rows[300][0]


def _extra(rows):
    rows[100].append("1.0")


def _comma_decimal(rows):
    rows[50][1] = "0,5"


def _jitter(rows):
    r = np.random.default_rng(3)
    for k, row in enumerate(rows):
        row[0] = f"{k * DT + r.uniform(-0.003, 0.003) + 0.003:.6f}"


def _quotes(rows):
    for r in rows:
        r[1] = f'"{r[1]}"'


def _spaces(rows):
    for r in rows:
        r[2] = f"  {r[2]} "


def _sci_time(rows):
    for k, r in enumerate(rows):
        r[0] = f"{k * DT:.3e}"


def _big_jump(rows):
    for k in range(300, N):
        rows[k][0] = f"{1000.0 + k * DT:.2f}"


#: (name, maker -> text or bytes, {reader: error pattern} (readers not named return data), check)
READERS = ["csv", "csv@100Hz", "table@100Hz"]
ALL_ERR = dict.fromkeys(READERS)


def errs(pattern, only=None):
    return {r: pattern for r in (only or READERS)}


def _read(reader, p):
    from fdikit.io import read_csv, read_log

    if reader == "csv":
        return read_csv(p)
    if reader == "csv@100Hz":
        return read_csv(p, rate=100.0)
    return read_log(p, rate=100.0)


def _ref(reader, tmp):
    p = tmp / "ref.csv"
    if not p.exists():
        p.write_text(to_text(base_rows()))
    return _read(reader, p)


def chk_same(s, ref, reader):
    """Equal to the clean log (same times, values, validity)."""
    assert s.names == ref.names
    assert np.array_equal(s.t, ref.t), "the time axis changed"
    assert np.array_equal(s.values, ref.values, equal_nan=True)
    assert np.array_equal(s.valid, ref.valid)


def chk_outside(lo, hi, *, margin=0.05):
    """Equal to the clean log outside [lo - margin, hi + margin]; invalid inside where gridded."""

    def chk(s, ref, reader):
        for k, t in enumerate(s.t):
            if lo - margin <= t <= hi + margin:
                continue
            j = int(np.searchsorted(ref.t, t))
            assert j < ref.t.size and ref.t[j] == t, f"sample at {t} not in the clean log"
            assert np.array_equal(s.values[0, k], ref.values[0, j], equal_nan=True), f"value changed at {t}"

    return chk


def chk_gap(lo, hi):
    """Gap [lo, hi): gridded samples strictly inside are invalid, with a reason; outside unchanged.
    The causal grid holds the last sample for max_gap = 3 source periods (0.03 s at 100 Hz) first."""

    def chk(s, ref, reader):
        chk_outside(lo, hi)(s, ref, reader)
        inside = (s.t > lo + 0.035) & (s.t < hi - 0.02)
        if reader == "csv":
            assert not inside.any()  # the file's own stamps: no sample in the gap at all
            return
        assert inside.any() and not s.valid[0][inside].any(), "a gap was bridged"
        k = int(np.flatnonzero(inside)[0])
        assert "gap" in s.invalid_reason(k)

    return chk


def chk_invalid(lo, hi, col, *, held=False):
    """Channel ``col`` invalid on [lo, hi) (and nowhere far outside); others unchanged. ``held``:
    the cells are empty (no samples), so the causal grid holds the last one for 3 periods first."""

    def chk(s, ref, reader):
        c = s.names.index(col)
        m = (s.t >= lo + (0.035 if held else 0.015)) & (s.t < hi - 0.015)
        assert m.any() and not s.valid[0, m, c].any(), "a bad cell was not flagged"
        far = (s.t < lo - 0.05) | (s.t > hi + 0.05)
        assert s.valid[0, far, c].all(), "good samples flagged"
        others = [j for j in range(len(s.names)) if j != c]
        assert np.array_equal(s.values[0][:, others], ref.values[0][:, others], equal_nan=True)

    return chk


def chk_value(t_at, col, value):
    def chk(s, ref, reader):
        c = s.names.index(col)
        k = int(np.flatnonzero(np.isclose(s.t, t_at, rtol=0, atol=1e-9))[0])
        assert s.values[0, k, c] == value and s.valid[0, k, c]

    return chk


def chk_epoch(s, ref, reader):
    assert np.array_equal(s.t, ref.t), "epoch time did not rebase to the clean axis exactly"
    assert np.array_equal(s.values, ref.values, equal_nan=True)
    assert s.t0 == 1_700_000_000.0 and s.time_origin is not None


def chk_shifted(shift):
    def chk(s, ref, reader):
        np.testing.assert_allclose(s.t, ref.t + shift, rtol=0, atol=1e-9)
        if reader != "csv":
            np.testing.assert_allclose(s.values, ref.values, rtol=0, atol=1e-12)
        else:
            assert np.array_equal(s.values, ref.values)

    return chk


def chk_any(s, ref, reader):
    """Sound data is enough (check_log ran)."""


def chk_jitter(s, ref, reader):
    if reader != "csv":
        assert s.valid.all()  # jitter is not a gap
        np.testing.assert_allclose(np.diff(s.t), DT, rtol=0, atol=1e-9)


def chk_one_col_invalid(col):
    def chk(s, ref, reader):
        assert not s.valid[0, :, s.names.index(col)].any()

    return chk


def chk_len(n):
    def chk(s, ref, reader):
        assert s.n_samples == n

    return chk


def _no_data_rows():
    return errs("no data rows", ["csv", "csv@100Hz"]) | {"table@100Hz": "no rows"}


TEXT_ROW = 123  # data row of the text cell
ARTEFACT_TABLE = [
    # gaps
    ("gap_0.5s", a_gap(2.0, 2.5), {}, chk_gap(2.0, 2.5)),
    ("gap_3s", a_gap(1.0, 4.0), {}, chk_gap(1.0, 4.0)),
    ("gap_after_first", a_gap(0.01, 0.5), {}, chk_gap(0.0, 0.5)),
    ("gap_before_last", a_gap(5.5, 5.99), {}, chk_gap(5.49, 5.99)),
    ("gap_10_periods", a_gap(3.0, 3.1), {}, chk_gap(3.0, 3.1)),
    ("jump_1000s", a_rows(_big_jump), {}, chk_any),
    # NaN blocks and bad values
    ("nan_block_empty_1s", a_cells(2.0, 3.0, 1, ""), {}, chk_invalid(2.0, 3.0, "x", held=True)),
    ("nan_block_text_1s", a_cells(2.0, 3.0, 2, "nan"), {}, chk_invalid(2.0, 3.0, "y")),
    ("nan_single", a_cells(2.0, 2.01, 3, "NaN"), {}, chk_outside(1.98, 2.02)),
    ("na_texts", a_cells(1.0, 1.05, 1, "NA"), {"table@100Hz": "not a number"}, chk_invalid(1.0, 1.05, "x")),
    (
        "null_text",
        a_cells(1.0, 1.05, 1, "null"),
        {"table@100Hz": "not a number"},
        chk_invalid(1.0, 1.05, "x"),
    ),
    (
        "all_empty_column",
        a_cells(-1, 99, 1, ""),
        {"table@100Hz": "'x' has no samples"},
        chk_one_col_invalid("x"),
    ),
    ("all_nan_column", a_cells(-1, 99, 1, "nan"), {}, chk_one_col_invalid("x")),
    ("inf_cell", a_cells(2.0, 2.01, 1, "inf"), {}, chk_outside(1.98, 2.02)),
    ("neg_inf_cell", a_cells(2.0, 2.01, 1, "-inf"), {}, chk_outside(1.98, 2.02)),
    ("overflow_1e400", a_cells(2.0, 2.01, 1, "1e400"), {}, chk_outside(1.98, 2.02)),
    ("spike_1e300", a_cells(2.0, 2.01, 1, "1e300"), {}, chk_value(2.0, "x", 1e300)),
    ("spike_-1e300", a_cells(2.0, 2.01, 2, "-1e300"), {}, chk_value(2.0, "y", -1e300)),
    ("huge_1e308", a_cells(0.0, 6.0, 3, "1e308"), {}, chk_value(3.0, "z", 1e308)),
    ("tiny_5e-324", a_cells(2.0, 2.01, 3, "5e-324"), {}, chk_value(2.0, "z", 5e-324)),
    # timestamps
    ("negative_start", a_time(lambda k: k * DT - 3.0, "{:.2f}"), {}, chk_shifted(-3.0)),
    (
        "zero_timestamps",
        a_time(lambda k: "0"),
        errs("not strictly increasing", ["csv", "csv@100Hz"]),
        chk_len(1),
    ),
    (
        "all_negative_decreasing",
        a_time(lambda k: -k * DT, "{:.2f}"),
        errs("not strictly increasing|goes backwards"),
        chk_any,
    ),
    (
        "duplicate_row",
        a_rows(_dup_row),
        errs("not strictly increasing at data row 200", ["csv", "csv@100Hz"]),
        chk_outside(1.98, 2.0),
    ),
    (
        "duplicate_time_other_value",
        a_rows(_dup_time),
        errs("not strictly increasing at data row 200", ["csv", "csv@100Hz"]),
        chk_outside(1.97, 2.02),
    ),
    (
        "backwards_time",
        a_rows(_back),
        errs(r"not strictly increasing at data row 301|goes backwards at row 301"),
        chk_any,
    ),
    (
        "time_nan",
        a_cells(3.0, 3.01, 0, "nan"),
        errs("not finite.*data row 300|not finite at row 300"),
        chk_any,
    ),
    ("time_empty", a_cells(3.0, 3.01, 0, ""), errs("empty at data row 300|empty at row 300"), chk_any),
    (
        "time_text",
        a_cells(3.0, 3.01, 0, "12:00:01"),
        errs("data row 300.*not a number|line 302.*not a number"),
        chk_any,
    ),
    ("epoch_s", a_epoch("s"), {}, chk_epoch),
    ("epoch_ms", a_epoch("ms"), {}, chk_epoch),
    ("epoch_us", a_epoch("us"), {}, chk_epoch),
    ("epoch_ns", a_epoch("ns"), {}, chk_epoch),
    ("jitter_30pct", a_rows(_jitter), {}, chk_jitter),
    ("sci_notation_time", a_rows(_sci_time), {}, chk_shifted(0.0)),
    # file structure
    ("truncated_10pct", a_truncate(0.1), errs("fields.*truncated"), chk_any),
    ("truncated_50pct", a_truncate(0.5), errs("fields.*truncated"), chk_any),
    ("truncated_90pct", a_truncate(0.9), errs("fields.*truncated"), chk_any),
    (
        "semicolon_delimiter",
        lambda: to_text(base_rows(), sep=";"),
        errs("';' or tabs", ["csv", "csv@100Hz"]) | {"table@100Hz": "no time column"},
        chk_any,
    ),
    (
        "tab_delimiter",
        lambda: to_text(base_rows(), sep="\t"),
        errs("';' or tabs", ["csv", "csv@100Hz"]) | {"table@100Hz": "no time column"},
        chk_any,
    ),
    ("bom", lambda: "\ufeff" + to_text(base_rows()), {"table@100Hz": "no time column"}, chk_same),
    ("crlf", lambda: to_text(base_rows(), eol="\r\n"), {}, chk_same),
    ("quoted_numbers", a_rows(_quotes), {}, chk_same),
    ("padded_cells", a_rows(_spaces), {}, chk_same),
    ("empty_file", a_text(""), errs("empty"), chk_any),
    ("blank_lines_only", a_text("\n\n  \n"), errs("empty|no time column|no rows"), chk_any),
    ("header_only", a_text("t,x,y,z\n"), _no_data_rows(), chk_any),
    ("header_and_blank_lines", a_text("t,x,y,z\n\n\n"), _no_data_rows(), chk_any),
    (
        "text_cell",
        a_cells(TEXT_ROW * DT, TEXT_ROW * DT + 0.005, 2, "abc"),
        errs(rf"column 'y'.*data row {TEXT_ROW}", ["csv", "csv@100Hz"])
        | {"table@100Hz": rf"line {TEXT_ROW + 2}, column 'y'"},
        chk_any,
    ),
    ("text_cell_comma_decimal", a_rows(_comma_decimal), errs("fields"), chk_any),
    (
        "duplicate_columns",
        lambda: to_text(base_rows(), header=("t", "x", "x", "z")),
        errs("duplicated column"),
        chk_any,
    ),
    (
        "missing_time_column",
        lambda: to_text(base_rows(), header=("clock", "x", "y", "z")),
        errs("no time column"),
        chk_any,
    ),
    (
        "only_time_column",
        lambda: "t\n" + "\n".join(f"{k * DT:.2f}" for k in range(10)) + "\n",
        errs("no channel besides the time column"),
        chk_any,
    ),
    ("extra_field", a_rows(_extra), errs("line 102 has 5 fields"), chk_any),
    (
        "binary_garbage",
        lambda: bytes(np.random.default_rng(1).integers(0, 256, 3000, dtype=np.uint8)),
        errs("not utf-8|no time column|empty|cannot be parsed|fields"),
        chk_any,
    ),
    (
        "latin1_header",
        lambda: to_text(base_rows(), header=("t", "x\xb0", "y", "z")).encode("latin-1"),
        errs("not utf-8"),
        chk_any,
    ),
    (
        "nul_bytes",
        lambda: to_text(base_rows()).replace("0.1", "0\x00.1", 1),
        errs("not a number|cannot be parsed|nul|line"),
        chk_any,
    ),
    ("single_row", lambda: "t,x,y,z\n0.0,1,2,3\n", {}, chk_len(1)),
    ("ns_as_seconds", a_epoch("ns"), {}, chk_epoch),  # auto unit; the explicit "s" is an API case
]


def _artefact_params():
    out = []
    for name, make, errors, chk in ARTEFACT_TABLE:
        for reader in READERS:
            out.append(pytest.param(make, errors.get(reader), chk, reader, id=f"{name}-{reader}"))
    return out


ARTEFACTS = _artefact_params()


@pytest.fixture(scope="module")
def reftmp(tmp_path_factory):
    return tmp_path_factory.mktemp("refs")


@pytest.mark.parametrize("make, error, chk, reader", ARTEFACTS)
def test_artefact(make, error, chk, reader, tmp_path, reftmp):
    content = make()
    p = tmp_path / "log.csv"
    if isinstance(content, bytes):
        p.write_bytes(content)
    else:
        p.write_bytes(content.encode("utf-8"))
    if error is not None:
        expect_error(lambda: _read(reader, p), error)
        return
    s = check_log(_read(reader, p))
    chk(s, _ref(reader, reftmp), reader)


# =====================================================================================
# 2. artefacts as samples into a running monitor (grown from test_bad_input_monitor.py)
# =====================================================================================
T = 300
CHANNELS = ["force", "pos1", "pos2"]


@pytest.fixture(scope="module")
def two_mass_setup():
    from fdikit.faults import Bias
    from fdikit.residuals import design_observer_residual
    from fdikit.systems import two_mass

    rec = two_mass.record([Bias("sensor:pos2", 0.01, start=1.5)], 1, 11, duration=(T - 1) * two_mass.DT)
    nominal = two_mass.record([], 1, 12, duration=(T - 1) * two_mass.DT)
    design = design_observer_residual(
        two_mass.model(), dt=two_mass.DT, Q=np.eye(4) * 1e-8, R=np.eye(2) * two_mass.NOISE_STD**2
    )
    return rec, nominal, design


def build_monitor(design, decision=False):
    from fdikit.detect import GLRT, MHSSPT, Hold, UniformMeanGaussian
    from fdikit.monitor import Decision, Monitor
    from fdikit.residuals import ObserverResidual
    from fdikit.systems import two_mass

    gen = ObserverResidual(design)
    glrt = GLRT(gen.output_names, 0.0, two_mass.NOISE_STD**2, W=10)
    return Monitor(
        [gen],
        [
            glrt,
            Hold(glrt.output_names, 50.0, Z=3, absolute=False),
            MHSSPT(
                ["r:pos2"],
                {
                    "ok": UniformMeanGaussian([0], [0], [0.003]),
                    "bias": UniformMeanGaussian([0.004], [0.05], [0.003]),
                },
                p=1e-3,
                q=1e-3,
            ),
        ],
        Decision(["r:pos1:glrt:alarm", "r:pos2:glrt:alarm"]) if decision else None,
        on_invalid="hold",
    )


def stream(design, values, times, decision=False):
    mon = build_monitor(design, decision)
    mon.reset(1)
    R, S, invalid, events, status, gaps = [], [], [], [], [], []
    for k, t in enumerate(times):
        r, s, ev = mon.step(float(t), values[:, k], CHANNELS)
        R.append(r[0])
        S.append(s[0])
        events += ev
        status.append(getattr(mon, "last_status", None))
        gaps.append(getattr(mon, "last_gap", None))
        if mon.last_invalid is not None:
            assert isinstance(mon.last_invalid, str) and mon.last_invalid
            invalid.append(k)
    R, S = np.array(R), np.array(S)
    assert np.all(np.isfinite(R)) and np.all(np.isfinite(S)), "NaN or inf reached an output"
    mon.trace = {"status": status, "gaps": gaps}
    return R, S, invalid, events, mon


def corrupt(rec, kind, channel, start, length):
    v = rec.values.copy()
    t = rec.t.copy()
    ks = list(range(start, min(start + length, T)))
    c = CHANNELS.index(channel)
    if kind in ("nan", "nan_block"):
        v[0, ks, c] = np.nan
    elif kind == "inf":
        v[0, ks, c] = np.inf
    elif kind == "-inf":
        v[0, ks, c] = -np.inf
    elif kind == "dropout":
        v[0, ks, :] = np.nan
    elif kind == "dup_time":
        t[ks] = t[start - 1]
    elif kind == "back_time":
        t[ks] = t[start - 1] - 0.005
    elif kind == "spike_1e300":
        v[0, ks, c] = 1e300
    elif kind == "spike_1e200":
        v[0, ks, c] = -1e200
    return v, t, ks


SIMPLE_KINDS = ["nan", "inf", "-inf", "dropout", "dup_time", "back_time"]
SPIKE_KINDS = ["spike_1e300", "spike_1e200"]
POSITIONS = ((1, 1), (50, 3), (160, 25), (T - 2, 2))
MONITOR = [
    pytest.param(k, ch, s, n, id=f"{k}-{ch}-{s}+{n}")
    for k in SIMPLE_KINDS
    for ch in CHANNELS
    for s, n in POSITIONS
] + [
    pytest.param(k, ch, s, n, id=f"{k}-{ch}-{s}+{n}")  # max_abs: an invalid sample, never fed to a filter
    for k in SPIKE_KINDS
    for ch in CHANNELS
    for s, n in POSITIONS
]


@pytest.mark.parametrize("kind, channel, start, length", MONITOR)
def test_monitor_artefact(two_mass_setup, kind, channel, start, length):
    rec, _, design = two_mass_setup
    v, t, bad = corrupt(rec, kind, channel, start, length)
    R, S, invalid, _, _ = stream(design, v, t)
    assert invalid == bad, "flagged samples differ from the corrupted ones"
    from fdikit import Signals

    good = np.setdiff1d(np.arange(T), bad)
    ref = build_monitor(design).stream(Signals(t[good], v[:, good], CHANNELS))
    np.testing.assert_array_equal(R[good], ref.residuals.values[0])
    np.testing.assert_array_equal(S[good], ref.statistics.values[0])


GAPS = [
    pytest.param(kind, start, n, id=f"{kind}-{start}+{n}")
    for kind in ("time_gap", "nan_block")
    for start, n in ((60, 50), (150, 20), (200, 80), (30, 100))
]


@pytest.mark.parametrize("kind, start, n", GAPS)
def test_monitor_gap_announces_nothing(two_mass_setup, kind, start, n):
    """A nominal record with a gap (samples cut out: the plant moved on; or a NaN block on every
    channel): outputs stay finite, the gap is flagged, and no announcement follows it."""
    _, nom, design = two_mass_setup
    if kind == "time_gap":
        keep = np.r_[0:start, start + n : T]
        v, t = nom.values[:, keep], nom.t[keep]
        first_after = start
    else:
        v = nom.values.copy()
        v[0, start : start + n, :] = np.nan
        t = nom.t
        first_after = start + n
    _R, _S, invalid, events, mon = stream(design, v, t, decision=True)
    if kind == "time_gap":
        assert mon.trace["gaps"][first_after] is not None, "the gap was not reported"
    else:
        assert invalid == list(range(start, start + n)), "the NaN block was not flagged sample by sample"
    assert mon.trace["status"][first_after] == "warmup", "no warm-up after the gap"
    assert events == [], f"announcements caused by the gap: {events}"


# =====================================================================================
# 3. CLI paths, in-process
# =====================================================================================
@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    from fdikit.cli import main
    from fdikit.faults import Bias
    from fdikit.systems import two_mass

    d = tmp_path_factory.mktemp("cli")
    shutil.copy(EXAMPLE, d / "monitor.toml")
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["design", str(d / "monitor.toml"), "--json"]) == 0
    s = two_mass.record([Bias("sensor:pos2", 0.012, start=4.0)], 1, 5)
    lines = ["time,F,P1,P2"] + [
        f"{t:.2f},{float(a)!r},{float(1000 * b)!r},{float(1000 * c)!r}"
        for t, a, b, c in zip(s.t, s["force"][0], s["pos1"][0], s["pos2"][0], strict=True)
    ]
    (d / "log.csv").write_text("\n".join(lines) + "\n")
    epoch = ["time,F,P1,P2"] + [
        f"{1_700_000_000 + k // 100}.{k % 100:02d}," + ln.split(",", 1)[1] for k, ln in enumerate(lines[1:])
    ]
    (d / "epoch.csv").write_text("\n".join(epoch) + "\n")
    (d / "empty.csv").write_text("")
    (d / "header.csv").write_text("time,F,P1,P2\n")
    bad = lines[:]
    bad[40] = bad[40].rsplit(",", 1)[0] + ",abc"
    (d / "text.csv").write_text("\n".join(bad) + "\n")
    (d / "semicolon.csv").write_text("\n".join(x.replace(",", ";") for x in lines) + "\n")
    (d / "nocol.csv").write_text("\n".join(",".join(x.split(",")[:3]) for x in lines) + "\n")
    (d / "afile").write_text("not a folder")
    (d / "notoml.toml").write_text("[monitor\nname = ")
    (d / "somedir").mkdir()
    return d


def run_cli(argv, stdin: str | None = None):
    """fdikit.cli.main in-process: (exit code, stdout, stderr); a traceback fails the case."""
    from fdikit.cli import main

    out, err = io.StringIO(), io.StringIO()
    old_stdin = None
    if stdin is not None:
        import sys

        old_stdin, sys.stdin = sys.stdin, io.StringIO(stdin)
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                rc = main([str(a) for a in argv])
            except SystemExit as exc:  # argparse: usage errors exit 2 with a message
                rc = exc.code if isinstance(exc.code, int) else 1
    finally:
        if old_stdin is not None:
            import sys

            sys.stdin = old_stdin
    assert "Traceback" not in err.getvalue() + out.getvalue()
    return rc, out.getvalue(), err.getvalue()


def M(*extra, log="log.csv"):
    return ["monitor", f"@{log}", "--config", "@monitor.toml", *extra]


#: (id, argv with @name for files of the workdir, expected message pattern, marks)
CLI_TABLE = [
    ("missing_log", M(log="nope.csv"), "nope.csv.*(no such|does not exist)", ()),
    ("log_is_dir", M(log="somedir"), "somedir.*(directory|no such|not a)", ()),
    ("empty_log", M(log="empty.csv"), "empty", ()),
    ("header_only_log", M(log="header.csv"), "no data rows", ()),
    ("text_cell_log", M(log="text.csv"), r"column 'P2'.*data row 39 \(line 41\)", ()),
    ("semicolon_log", M(log="semicolon.csv"), "';' or tabs", ()),
    ("log_lacks_column", M(log="nocol.csv"), "P2", ()),
    ("missing_config", ["monitor", "@log.csv", "--config", "@none.toml"], "none.toml.*no such config", ()),
    ("config_not_toml", ["monitor", "@log.csv", "--config", "@notoml.toml"], "not valid TOML", ()),
    (
        "config_is_dir",
        ["monitor", "@log.csv", "--config", "@somedir"],
        "somedir",
        (),
    ),
    ("events_missing_dir", M("--events", "@no/dir/ev.jsonl"), "no/dir|does not exist|folder", ()),
    ("stats_missing_dir", M("--stats", "@no/dir/st.parquet"), "no/dir|does not exist|folder", ()),
    ("plot_missing_dir", M("--plot", "@no/dir/p.png"), "no/dir|does not exist|folder", ()),
    ("report_missing_dir", M("--report", "@no/dir/r.html"), "no/dir|does not exist|folder", ()),
    ("report_wrong_suffix", M("--report", "@r.txt"), r"\.html", ()),
    ("events_parent_is_file", M("--events", "@afile/ev.jsonl"), "afile", ()),
    ("stats_parent_is_file", M("--stats", "@afile/st.parquet"), "afile", ()),
    ("plot_parent_is_file", M("--plot", "@afile/p.png"), "afile", ()),
    ("events_is_dir", M("--events", "@somedir"), "somedir", ()),
    ("stdin_without_follow", ["monitor", "-", "--config", "@monitor.toml"], "needs --follow", ()),
    ("follow_with_json", M("--follow", "--json"), "does not take --json", ()),
    ("resume_without_checkpoint", M("--follow", "--resume"), "--resume needs --checkpoint", ()),
    (
        "checkpoint_every_0",
        M("--follow", "--checkpoint", "@ck.npz", "--checkpoint-every", "0"),
        "checkpoint-every",
        (),
    ),
    ("checkpoint_every_text", M("--follow", "--checkpoint-every", "ten"), "invalid int", ()),
    ("unknown_flag", M("--frobnicate"), "unrecognized arguments", ()),
    ("unknown_subcommand", ["frobnicate"], "invalid choice", ()),
    ("monitor_without_config", ["monitor", "@log.csv"], "--config", ()),
    ("monitor_without_log", ["monitor", "--config", "@monitor.toml"], "required|log", ()),
    ("bad_input_choice", M("--follow", "--input", "xml"), "invalid choice", ()),
    ("design_missing_config", ["design", "@none.toml"], "no such config", ()),
    ("design_not_toml", ["design", "@notoml.toml"], "not valid TOML", ()),
    ("design_unknown_flag", ["design", "@monitor.toml", "--fast"], "unrecognized arguments", ()),
    ("reconstruct_h_0", ["reconstruct", "aircraft", "--h", "0"], r"--h|step", ()),
    ("reconstruct_h_negative", ["reconstruct", "aircraft", "--h", "-1e-3"], r"--h|step", ()),
    ("reconstruct_h_nan", ["reconstruct", "aircraft", "--h", "nan"], r"--h|step", ()),
    ("reconstruct_h_text", ["reconstruct", "aircraft", "--h", "small"], "invalid float", ()),
    ("reconstruct_unknown_system", ["reconstruct", "zeppelin"], "invalid choice", ()),
    (
        "follow_missing_log",
        M("--follow", log="nope.csv"),
        "nope.csv",
        (),
    ),
]


def _expand(argv, d):
    return [str(d / a[1:]) if isinstance(a, str) and a.startswith("@") else a for a in argv]


CLI = [pytest.param(argv, pat, id=name, marks=list(marks)) for name, argv, pat, marks in CLI_TABLE]


@pytest.mark.parametrize("argv, pattern", CLI)
def test_cli_error(workdir, argv, pattern):
    rc, out, err = run_cli(_expand(argv, workdir))
    assert rc != 0, f"exit code 0 for a bad invocation; stdout {out[-300:]!r}"
    assert re.search(pattern, err, re.IGNORECASE | re.DOTALL), (
        f"stderr {err[-500:]!r} does not name {pattern!r}"
    )
    assert not list(workdir.glob("no")), "an output folder was created"


GOOD_CLI = ["batch", "batch_epoch", "follow", "follow_garbled", "follow_epoch"]
CLI_OK = [
    pytest.param(
        k,
        id=f"ok-{k}",
        marks=[],
    )
    for k in GOOD_CLI
]


def _events(text):
    return [json.loads(x) for x in text.splitlines() if x.strip().startswith("{")]


@pytest.mark.parametrize("kind", CLI_OK)
def test_cli_runs_bad_but_readable_logs(workdir, kind):
    """Logs a user will have (epoch time, garbled lines in a live stream) run and give the events
    of the clean log: nothing silently different."""
    rc, out, err = run_cli(_expand(M("--json"), workdir))
    assert rc == 0, err
    ref = json.loads(out)
    ref_t = [e["t"] for e in ref["events"]]
    assert ref_t, "the reference log has announcements"
    if kind == "batch":
        assert all(math.isfinite(v) for v in ref["max_statistics"].values())
        return
    if kind == "batch_epoch":
        rc, out, err = run_cli(_expand(M("--json", log="epoch.csv"), workdir))
        assert rc == 0, err
        got = json.loads(out)
        assert [e["t"] for e in got["events"]] == ref_t and got["samples"] == ref["samples"]
        return
    text = (workdir / ("epoch.csv" if kind == "follow_epoch" else "log.csv")).read_text().splitlines()
    if kind == "follow_garbled":
        text = [*text[:20], "garbage line", "1.0,2.0", "", "x,y,z,w", *text[20:]]
    rc, out, err = run_cli(
        ["monitor", "-", "--config", workdir / "monitor.toml", "--follow"], stdin="\n".join(text) + "\n"
    )
    assert rc == 0, err
    recs = _events(out)
    ev = [r["t"] for r in recs if r.get("announcement")]
    assert ev == ref_t
    if kind == "follow_garbled":
        assert sum("invalid" in r for r in recs) >= 3


# =====================================================================================
# 4. config semantics
# =====================================================================================
BASE_TOML = EXAMPLE.read_text() if EXAMPLE.exists() else ""


def cfg_set(section: str, key: str, value: str):
    """The example config with ``key = value`` set in ``[section]`` (added or replaced)."""

    def make(text=BASE_TOML):
        lines = text.splitlines()
        head = f"[{section}]"
        if head not in lines:
            return text + f"\n{head}\n{key} = {value}\n"
        i = lines.index(head)
        j = i + 1
        while j < len(lines) and not lines[j].startswith("["):
            if re.match(rf"^{re.escape(key)}\s*=", lines[j]):
                lines[j] = f"{key} = {value}"
                return "\n".join(lines) + "\n"
            j += 1
        lines.insert(i + 1, f"{key} = {value}")
        return "\n".join(lines) + "\n"

    return make


def cfg_text(fn):
    return lambda text=BASE_TOML: fn(text)


CONFIG_TABLE = [
    # unknown keys
    ("unknown_section", cfg_text(lambda t: t + "\n[plots]\nx = 1\n"), r"unknown section \[plots\]", ()),
    ("unknown_key_monitor", cfg_set("monitor", "nmae", '"x"'), r"unknown key 'nmae' in \[monitor\]", ()),
    ("unknown_key_log", cfg_set("log", "delimiter", '";"'), r"unknown key 'delimiter' in \[log\]", ()),
    ("unknown_key_channel", cfg_set("channels.force", "gain", "2.0"), r"'gain' in \[channels.force\]", ()),
    ("unknown_key_decision", cfg_set("decision", "lvl", "0.5"), r"'lvl' in \[decision\]", ()),
    ("unknown_key_design", cfg_set("design", "recipie", '"x"'), r"'recipie' in \[design\]", ()),
    (
        "unknown_key_generator",
        cfg_text(lambda t: t.replace('artifact = "observer"', 'artifact = "observer"\nartefact = "x"')),
        r"'artefact' in \[generators\[0\]\]",
        (),
    ),
    # wrong types
    ("type_monitor_name", cfg_set("monitor", "name", "1"), r"\[monitor\].name must be str", ()),
    (
        "type_monitor_artifacts",
        cfg_set("monitor", "artifacts", "[1]"),
        r"\[monitor\].artifacts must be str",
        (),
    ),
    ("type_on_invalid", cfg_set("monitor", "on_invalid", "true"), r"on_invalid must be str", ()),
    ("type_max_gap", cfg_set("monitor", "max_gap", '"long"'), r"max_gap must be", ()),
    ("type_warmup", cfg_set("monitor", "warmup", "true"), r"warmup must be", ()),
    ("type_log_format", cfg_set("log", "format", "3"), r"format must be str", ()),
    ("type_log_time", cfg_set("log", "time", "0"), r"\[log\].time must be str", ()),
    ("type_log_rate", cfg_set("log", "rate", '"fast"'), r"rate must be", ()),
    ("type_log_dbc", cfg_set("log", "dbc", "1"), r"dbc must be str", ()),
    ("type_time_unit", cfg_set("log", "time_unit", "1000"), r"time_unit must be str", ()),
    ("type_scale", cfg_set("channels.pos1", "scale", '"mm"'), r"scale must be", ()),
    ("type_offset", cfg_set("channels.pos1", "offset", "[0]"), r"offset must be", ()),
    ("type_source", cfg_set("channels.pos1", "source", "1"), r"source must be str", ()),
    ("type_unit", cfg_set("channels.pos1", "unit", "1"), r"unit must be str", ()),
    ("type_min", cfg_set("channels.pos1", "min", '"low"'), r"min must be", ()),
    (
        "type_shared_source",
        cfg_set("channels.pos1", "shared_source", '"yes"'),
        r"shared_source must be bool",
        (),
    ),
    (
        "type_decision_channels",
        cfg_set("decision", "channels", '"r:pos1:alarm"'),
        r"channels must be list",
        (),
    ),
    ("type_decision_level", cfg_set("decision", "level", '"high"'), r"level must be", ()),
    ("type_decision_names", cfg_set("decision", "names", "1"), r"names must be dict", ()),
    (
        "type_generators",
        cfg_text(
            lambda t: t.replace('[[generators]]\nartifact = "observer"', "").replace(
                "[monitor]", 'generators = "observer"\n[monitor]'
            )
        ),
        r"generators must be an array",
        (),
    ),
    (
        "type_artifact_name",
        cfg_text(lambda t: t.replace('artifact = "observer"', "artifact = 1")),
        r"artifact must be str",
        (),
    ),
    (
        "design_params_edited_after_design",
        cfg_text(lambda t: t.replace("[design.params]", "[design.params.x]")),
        r"fdikit design",
        (),
    ),
    # ranges
    (
        "range_on_invalid",
        cfg_set("monitor", "on_invalid", '"ignore"'),
        r"on_invalid must be 'hold' or 'raise'",
        (),
    ),
    ("range_format", cfg_set("log", "format", '"xml"'),
     r"\[log\].format must be one of .*'auto', 'csv', 'can'.*got 'xml'", ()),
    ("range_time_unit", cfg_set("log", "time_unit", '"minutes"'), r"time_unit must be one of", ()),
    ("range_scale_zero", cfg_set("channels.pos1", "scale", "0"), r"scale must be finite and non-zero", ()),
    ("range_scale_nan", cfg_set("channels.pos1", "scale", "nan"), r"scale must be finite", ()),
    ("range_offset_inf", cfg_set("channels.pos1", "offset", "inf"), r"offset finite", ()),
    ("range_max_gap_zero", cfg_set("monitor", "max_gap", "0"), r"max_gap must be a finite number > 0", ()),
    ("range_max_gap_negative", cfg_set("monitor", "max_gap", "-1.0"), r"max_gap must be", ()),
    ("range_warmup_negative", cfg_set("monitor", "warmup", "-1"), r"warmup must be a finite number >= 0", ()),
    ("range_max_abs_zero", cfg_set("monitor", "max_abs", "0"), r"max_abs must be", ()),
    ("range_max_abs_inf", cfg_set("monitor", "max_abs", "inf"), r"max_abs must be", ()),
    ("range_rate_zero", cfg_set("log", "rate", "0"), r"rate", ()),
    ("range_rate_negative", cfg_set("log", "rate", "-100"), r"rate", ()),
    ("range_rate_nan", cfg_set("log", "rate", "nan"), r"rate", ()),
    ("range_level_above_1", cfg_set("decision", "level", "1.5"), r"level", ()),
    ("range_level_negative", cfg_set("decision", "level", "-0.1"), r"level", ()),
    (
        "range_min_above_max",
        cfg_text(lambda t: t.replace('unit = "N"', 'unit = "N"\nmin = 5.0\nmax = -5.0')),
        r"min = 5.0 N must be below max = -5.0 N",
        (),
    ),
    (
        "range_min_equals_max",
        cfg_text(lambda t: t.replace('unit = "N"', 'unit = "N"\nmin = 1.0\nmax = 1.0')),
        r"must be below max",
        (),
    ),
    ("range_max_rate_zero", cfg_set("channels.force", "max_rate", "0"), r"max_rate must be > 0", ()),
    ("range_spike_negative", cfg_set("channels.force", "spike", "-1"), r"spike must be > 0", ()),
    ("range_plausibility_nan", cfg_set("channels.force", "max", "nan"), r"max must be finite", ()),
    # duplicate sources, unknown channels
    (
        "duplicate_source",
        cfg_text(lambda t: t.replace('source = "P2"', 'source = "P1"')),
        r"channels \['pos1', 'pos2'\] all read the source column 'P1'",
        (),
    ),
    (
        "duplicate_source_one_shared",
        cfg_text(lambda t: t.replace('source = "P2"', 'source = "P1"\nshared_source = true')),
        r"all read the source column 'P1'",
        (),
    ),
    ("decision_unknown_channel", cfg_set("decision", "channels", '["r:pos3:alarm"]'), r"r:pos3:alarm", ()),
    ("decision_names_unknown", cfg_set("decision", "names", '{ "r:pos9:alarm" = "x" }'), r"r:pos9:alarm", ()),
    (
        "artifact_reads_undefined_channel",
        cfg_text(lambda t: t.replace("[channels.force]", "[channels.thrust]")),
        r"reads channels \['force'\]",
        (),
    ),
    ("decision_channels_empty", cfg_set("decision", "channels", "[]"), r"channels", ()),
    # structure
    (
        "no_channels",
        cfg_text(lambda t: re.sub(r"\[channels\.\w+\][^\[]*", "", t)),
        r"\[channels\] must name",
        (),
    ),
    (
        "no_generators",
        cfg_text(lambda t: t.replace('[[generators]]\nartifact = "observer"\n', "")),
        r"at least one \[\[generators\]\]",
        (),
    ),
    (
        "generator_without_artifact",
        cfg_text(lambda t: t.replace('[[generators]]\nartifact = "observer"', "[[generators]]")),
        r"needs an 'artifact' name",
        (),
    ),
    (
        "decision_without_channels",
        cfg_text(lambda t: re.sub(r"channels = \[.*\]\n", "", t)),
        r"\[decision\] needs 'channels'",
        (),
    ),
    (
        "decision_processor_and_channels",
        cfg_set("decision", "processor", '"hold"'),
        r"'channels' or 'processor', not both",
        (),
    ),
    (
        "design_recipe_and_plant",
        cfg_text(lambda t: t + "\n[design.plant]\nA = [[0.0]]\n"),
        r"plant and a recipe",
        (),
    ),
    (
        "missing_artifact",
        cfg_text(lambda t: t.replace('artifact = "hold"', 'artifact = "hold2"')),
        r"hold2",
        (),
    ),
    # files
    ("empty_file", cfg_text(lambda t: ""), r"\[channels\] must name", ()),
    ("not_toml", cfg_text(lambda t: "[monitor\n"), r"not valid TOML", ()),
    ("binary_garbage", cfg_text(lambda t: "\x00\x01\x02"), r"not valid TOML", ()),
    (
        "toml_array_as_table",
        cfg_text(lambda t: t.replace("[monitor]", "monitor = [1, 2]\n[dummy]")),
        r"monitor|unknown section",
        (),
    ),
]
CONFIG = [pytest.param(make, pat, id=name, marks=list(marks)) for name, make, pat, marks in CONFIG_TABLE]


@pytest.fixture(scope="module")
def designed(tmp_path_factory):
    """A folder with the example config's artifacts already designed (shared by config cases)."""
    from fdikit.monitor.config import load_config, run_design

    d = tmp_path_factory.mktemp("designed")
    shutil.copy(EXAMPLE, d / "monitor.toml")
    run_design(load_config(d / "monitor.toml"))
    return d


@pytest.mark.parametrize("make, pattern", CONFIG)
def test_config_semantics(designed, tmp_path, make, pattern):
    from fdikit.monitor.config import build_monitor as build
    from fdikit.monitor.config import load_config

    shutil.copytree(designed / "designs", tmp_path / "designs")
    p = tmp_path / "monitor.toml"
    p.write_text(make())

    def load_and_build():
        build(load_config(p))

    expect_error(load_and_build, pattern)


# =====================================================================================
# 5. artifacts
# =====================================================================================
def _hold(tmp):
    from fdikit.base.artifacts import save_artifact
    from fdikit.detect import Hold

    return save_artifact(tmp / "hold", Hold(["r:a", "r:b"], [0.5, 0.7], Z=3))


def _observer(tmp, designed):
    """A filter design large enough that its A matrix travels in the NPZ file."""
    from fdikit.base.artifacts import save_artifact
    from fdikit.residuals import FilterDesign

    rng = np.random.default_rng(5)
    n, m, p, q = 20, 2, 3, 4
    d = FilterDesign(
        rng.normal(size=(n, n)) / 10,
        rng.normal(size=(n, m)),
        rng.normal(size=(n, p)),
        rng.normal(size=(q, n)),
        rng.normal(size=(q, m)),
        rng.normal(size=(q, p)),
        0.01,
        ["u1", "u2"],
        ["y1", "y2", "y3"],
        [f"r{i}" for i in range(q)],
    )
    j = save_artifact(tmp / "filter", d)
    assert j.with_suffix(".npz").exists()
    return j


def _edit_json(path, fn):
    d = json.loads(path.read_text())
    fn(d)
    path.write_text(json.dumps(d))


def _npz_rewrite(path, fn):
    with np.load(path, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    fn(arrays)
    with open(path, "wb") as fh:
        np.savez(fh, **arrays)


def _first_key(z):
    return sorted(z)[0]


ARTIFACT_TABLE = [
    ("missing_json", "hold", lambda j: j.unlink(), r"no such artifact", ()),
    ("missing_npz", "observer", lambda j: j.with_suffix(".npz").unlink(), r"npz", ()),
    ("empty_json", "hold", lambda j: j.write_text(""), r"not a readable artifact", ()),
    ("truncated_json", "hold", lambda j: j.write_text(j.read_text()[:100]), r"not a readable artifact", ()),
    ("garbage_json", "hold", lambda j: j.write_bytes(b"\x00\xff\xfe"), r"not a readable artifact", ()),
    ("json_list", "hold", lambda j: j.write_text("[1, 2]"), r"not an fdikit artifact", ()),
    ("json_no_format", "hold", lambda j: _edit_json(j, lambda d: d.pop("format")), r"no format field", ()),
    (
        "other_format",
        "hold",
        lambda j: _edit_json(j, lambda d: d.update(format="fdikit-artifact/9")),
        r"artifact format",
        (),
    ),
    (
        "newer_version",
        "hold",
        lambda j: _edit_json(j, lambda d: d.update(fdikit_version="999.0")),
        r"newer than the installed",
        (),
    ),
    (
        "unknown_kind",
        "hold",
        lambda j: _edit_json(j, lambda d: d.update(kind="Frobnicator", **{"class": None})),
        r"Frobnicator|kind",
        (),
    ),
    (
        "class_outside_fdikit",
        "hold",
        lambda j: _edit_json(j, lambda d: d.update(**{"class": "os:system"})),
        r"os|fdikit",
        (),
    ),
    (
        "payload_missing",
        "hold",
        lambda j: _edit_json(j, lambda d: d.pop("payload")),
        r"'payload' is missing",
        (),
    ),
    (
        "payload_garbled",
        "hold",
        lambda j: _edit_json(j, lambda d: d.update(payload={"x": 1})),
        r"payload|Hold|key",
        (),
    ),
    (
        "channels_edited",
        "hold",
        lambda j: _edit_json(j, lambda d: d["channels"].update(inputs=["r:x", "r:y"])),
        r"channels",
        (),
    ),
    (
        "channels_not_object",
        "hold",
        lambda j: _edit_json(j, lambda d: d.update(channels=[1])),
        r"'channels' must be a JSON object",
        (),
    ),
    ("meta_not_object", "hold", lambda j: _edit_json(j, lambda d: d.update(meta="x")), r"'meta' must be", ()),
    (
        "npz_truncated",
        "observer",
        lambda j: j.with_suffix(".npz").write_bytes(j.with_suffix(".npz").read_bytes()[:200]),
        r"npz|corrupt|cannot",
        (),
    ),
    (
        "npz_garbage",
        "observer",
        lambda j: j.with_suffix(".npz").write_bytes(b"PK\x03\x04garbage"),
        r"npz|corrupt|cannot",
        (),
    ),
    (
        "npz_array_missing",
        "observer",
        lambda j: _npz_rewrite(j.with_suffix(".npz"), lambda z: z.pop(_first_key(z))),
        r"a\d|missing|npz",
        (),
    ),
    (
        "npz_shape_mismatch",
        "observer",
        lambda j: _npz_rewrite(
            j.with_suffix(".npz"), lambda z: z.update({_first_key(z): np.zeros((7, 7, 7))})
        ),
        r"shape",
        (),
    ),
    (
        "npz_dtype_mismatch",
        "observer",
        lambda j: _npz_rewrite(
            j.with_suffix(".npz"), lambda z: z.update({_first_key(z): z[_first_key(z)].astype(np.float32)})
        ),
        r"dtype|shape",
        (),
    ),
    (
        "npz_extra_array",
        "observer",
        lambda j: _npz_rewrite(j.with_suffix(".npz"), lambda z: z.update(zz=np.ones(2))),
        r"zz|array|manifest",
        (),
    ),
    (
        "npz_object_array",
        "observer",
        lambda j: _npz_rewrite(
            j.with_suffix(".npz"), lambda z: z.update({_first_key(z): np.array([{"a": 1}], dtype=object)})
        ),
        r"pickle|object|cannot|npz|shape|dtype",
        (),
    ),
    (
        "manifest_shapes_edited",
        "observer",
        lambda j: _edit_json(j, lambda d: d["shapes"][sorted(d["shapes"])[0]].update(shape=[99])),
        r"shape",
        (),
    ),
    (
        "manifest_array_ref_edited",
        "observer",
        lambda j: _edit_json(j, lambda d: d["arrays"].update({sorted(d["arrays"])[0]: "a999"})),
        r"a999|array|npz",
        (),
    ),
    ("wrong_kind_requested", "hold", None, r"is a Hold, expected a GLRT", ()),
    ("wrong_inputs_expected", "hold", None, r"inputs are", ()),
]
ARTIFACTS = [
    pytest.param(base, fn, pat, id=name, marks=list(marks)) for name, base, fn, pat, marks in ARTIFACT_TABLE
]


@pytest.mark.parametrize("base, fn, pattern", ARTIFACTS)
def test_artifact(designed, tmp_path, base, fn, pattern, request):
    from fdikit.base.artifacts import load_artifact

    j = _hold(tmp_path) if base == "hold" else _observer(tmp_path, designed)
    kw = {}
    name = request.node.callspec.id
    if name == "wrong_kind_requested":
        kw = {"kind": "GLRT"}
    elif name == "wrong_inputs_expected":
        kw = {"expect_inputs": ["r:z"]}
    else:
        fn(j)
    expect_error(lambda: load_artifact(j, **kw), pattern)


EXTRA_ARTIFACT = [
    "save_missing_folder",
    "save_parent_is_file",
    "umask_022",
    "umask_077",
    "stale_design",
    "checkpoint_garbage",
    "checkpoint_wrong_kind",
    "checkpoint_other_monitor",
]
_EXTRA_MARKS: dict = {}
ARTIFACT_FILES = [
    pytest.param(k, id=k, marks=[_EXTRA_MARKS[k]] if k in _EXTRA_MARKS else []) for k in EXTRA_ARTIFACT
]


@pytest.mark.parametrize("kind", ARTIFACT_FILES)
def test_artifact_files(designed, tmp_path, kind):
    from fdikit.base.artifacts import load_artifact, save_artifact
    from fdikit.detect import Hold

    h = Hold(["r"], 0.5, Z=2)
    if kind == "save_missing_folder":
        p = save_artifact(tmp_path / "new" / "deep" / "hold", h)
        assert load_artifact(p).Z == 2
    elif kind == "save_parent_is_file":
        (tmp_path / "f").write_text("x")
        expect_error(lambda: save_artifact(tmp_path / "f" / "hold", h), r"f")
    elif kind.startswith("umask"):
        mask = int(kind.split("_")[1], 8)
        old = os.umask(mask)
        try:
            p = save_artifact(tmp_path / "hold", h)
        finally:
            os.umask(old)
        assert (p.stat().st_mode & 0o777) == (0o666 & ~mask)
    elif kind == "stale_design":
        from fdikit.monitor.config import build_monitor as build
        from fdikit.monitor.config import load_config

        shutil.copytree(designed / "designs", tmp_path / "designs")
        text = EXAMPLE.read_text().replace("Z = 5", "Z = 7")
        (tmp_path / "monitor.toml").write_text(text)
        expect_error(lambda: build(load_config(tmp_path / "monitor.toml")), r"fdikit design")
    elif kind.startswith("checkpoint"):
        mon = build_monitor_from(designed)
        mon.reset(1)
        p = tmp_path / "ck.npz"
        if kind == "checkpoint_garbage":
            p.write_bytes(b"garbage")
            expect_error(lambda: mon.load_checkpoint(p), r"ck|checkpoint|state|corrupt|not")
        elif kind == "checkpoint_wrong_kind":
            from fdikit.base.state import save_state

            save_state(p, {"x": 1}, meta={"kind": "follow"})
            expect_error(lambda: mon.load_checkpoint(p), r"not a Monitor checkpoint")
        else:
            from fdikit.detect import GLRT
            from fdikit.monitor import Monitor

            other = Monitor([mon.generators[0]], [GLRT(mon.generators[0].output_names, 0.0, 1.0, W=5)])
            other.reset(1)
            other.save_checkpoint(p)
            expect_error(lambda: mon.load_checkpoint(p), r"channels")


def build_monitor_from(d):
    from fdikit.monitor.config import build_monitor as build
    from fdikit.monitor.config import load_config

    return build(load_config(d / "monitor.toml"))


# =====================================================================================
# 6. API misuse
# =====================================================================================
def _mon(designed):
    return build_monitor_from(designed)


def _obs(designed):
    return _mon(designed).generators[0]


def _glrt():
    from fdikit.detect import GLRT

    return GLRT(["r:a", "r:b"], 0.0, 1.0, W=5)


def _mhsspt():
    from fdikit.detect import MHSSPT, UniformMeanGaussian

    return MHSSPT(
        ["r"],
        {"ok": UniformMeanGaussian([0], [0], [1.0]), "bias": UniformMeanGaussian([1.0], [2.0], [1.0])},
        p=1e-3,
        q=1e-3,
    )


def _hold_c():
    from fdikit.detect import Hold

    return Hold(["r:a", "r:b"], [1.0, 2.0], Z=2)


def _nan_refused_state_kept(make, feed, pattern):
    """Feed a NaN into a component after a good sample: DataError, its state unchanged."""

    def case(designed):
        c = make(designed) if make in (_obs,) else make()
        c.reset(1)
        feed(c, 0.0)
        before = c.get_state()
        expect_error(lambda: feed(c, np.nan), pattern)
        after = c.get_state()
        assert json.dumps(before, default=repr, sort_keys=True) == json.dumps(
            after, default=repr, sort_keys=True
        )

    return case


def _feed_obs(c, x):
    c.step(np.array([[x]]), np.array([[x, x]]))


def _feed2(c, x):
    c.step(np.array([[x, x]]))


def _feed1(c, x):
    c.step(np.array([[x]]))


def _sig(*a, **k):
    from fdikit import Signals

    return lambda d: Signals(*a, **k)


def _call(fn):
    return lambda d: fn()


def _step_before_reset(d):
    mon = _mon(d)
    mon.step(0.0, {"force": 0.0, "pos1": 0.0, "pos2": 0.0})


def _mon_step(sample, names=None, t=0.0, reset=True, pre=None):
    def case(d):
        mon = _mon(d)
        mon.reset(1)
        if pre is not None:
            pre(mon)
        mon.step(t, sample, names)

    return case


def _mon_raise_mode(pre_t, t):
    def case(d):
        from fdikit.monitor import Monitor

        m = _mon(d)
        mon = Monitor(m.generators, m.processors, m.decision, on_invalid="raise")
        mon.reset(1)
        mon.step(pre_t, {"force": 0.0, "pos1": 0.0, "pos2": 0.0})
        mon.step(t, {"force": 0.0, "pos1": 0.0, "pos2": 0.0})

    return case


def _io(fn):
    return lambda d: fn()


def _rtg(**kw):
    from fdikit.io import resample_to_grid

    return _io(lambda: resample_to_grid(np.arange(5.0), np.arange(5.0), np.arange(3.0), **kw))


def _stg(series=None, **kw):
    from fdikit.io import series_to_grid

    return _io(
        lambda: series_to_grid(
            series if series is not None else {"x": (np.arange(5.0), np.arange(5.0))},
            {},
            **({"rate": 10.0} | kw),
        )
    )


SPEED_DBC = (
    'VERSION ""\nBO_ 180 SPEED: 8 XXX\n SG_ SPEED : 47|16@0+ (0.01,0) [0|250] "km/h" XXX\n'
    'BO_ 170 WHEELS: 8 XXX\n SG_ FL : 7|16@0+ (0.01,0) [0|250] "km/h" XXX\n'
    ' SG_ FR : 23|16@0+ (0.01,0) [0|250] "km/h" XXX\n'
)


def _db():
    import cantools

    return cantools.database.load_string(SPEED_DBC, database_format="dbc")


def _gridder(**kw):
    from fdikit.io import FrameGridder

    return _io(lambda: FrameGridder(_db(), **({"signals": ["SPEED.SPEED"], "rate": 10.0} | kw)))


def _gridder_push(frames):
    def case(d):
        from fdikit.io import FrameGridder

        g = FrameGridder(_db(), ["SPEED.SPEED"], 10.0)
        for f in frames:
            g.push(*f)

    return case


def _csv_call(text, **kw):
    def case(d):
        from fdikit.io import read_csv

        p = Path(d) / "api.csv"
        p.write_text(text)
        try:
            read_csv(p, **kw)
        finally:
            p.unlink()

    return case


def _read_log(**kw):
    def case(d):
        from fdikit.io import read_log

        p = Path(d) / "api.csv"
        p.write_text("t,x\n0,1\n0.1,2\n")
        try:
            read_log(p, **kw)
        finally:
            p.unlink()

    return case


def _candump_line(line):
    from fdikit.io import parse_candump_line

    return _io(lambda: parse_candump_line(line, 7))


def _logsignals(**kw):
    from fdikit.io import LogSignals

    return _io(lambda: LogSignals(np.arange(3.0), np.ones((3, 1)), ["a"], **kw))


API_TABLE = [
    ("monitor_step_before_reset", _step_before_reset, r"reset", ()),
    (
        "monitor_step_wrong_shape",
        _mon_step(np.zeros((1, 5)), ["force", "pos1", "pos2"]),
        r"must have shape",
        (),
    ),
    ("monitor_step_missing_channel", _mon_step({"force": 0.0, "pos1": 0.0}), r"lacks channel 'pos2'", ()),
    ("monitor_step_array_without_names", _mon_step(np.zeros((1, 3))), r"channel names", ()),
    (
        "monitor_step_duplicate_names",
        _mon_step(np.zeros((1, 4)), ["force", "pos1", "pos2", "pos2"]),
        r"twice",
        (),
    ),
    (
        "monitor_step_nan_time",
        _mon_step({"force": 0.0, "pos1": 0.0, "pos2": 0.0}, t=float("nan")),
        r"not finite",
        (),
    ),
    (
        "monitor_step_inf_time",
        _mon_step({"force": 0.0, "pos1": 0.0, "pos2": 0.0}, t=float("inf")),
        r"not finite",
        (),
    ),
    ("monitor_raise_nan", lambda d: _raise_nan(d), r"channel 'pos1' has a non-finite value", ()),
    ("monitor_raise_time_back", _mon_raise_mode(1.0, 0.5), r"not increasing", ()),
    ("monitor_raise_time_same", _mon_raise_mode(1.0, 1.0), r"not increasing", ()),
    ("monitor_bad_on_invalid", lambda d: _bad_on_invalid(d), r"on_invalid must be", ()),
    (
        "monitor_run_missing_channel",
        lambda d: _mon(d).run(_two_channel_signals()),
        r"unknown channel 'pos2'",
        (),
    ),
    ("monitor_processor_needs_missing", lambda d: _proc_missing(d), r"needs channels", ()),
    ("decision_unknown_channel", lambda d: _decision_unknown(d), r"decision needs channels", ()),
    (
        "obs_nan_state_kept",
        _nan_refused_state_kept(_obs, _feed_obs, r"non-finite|NaN|finite"),
        r"",
        (),
    ),
    (
        "glrt_nan_state_kept",
        _nan_refused_state_kept(lambda: _glrt(), _feed2, r"non-finite|NaN|finite"),
        r"",
        (),
    ),
    (
        "hold_nan_state_kept",
        _nan_refused_state_kept(lambda: _hold_c(), _feed2, r"non-finite|NaN|finite"),
        r"",
        (),
    ),
    (
        "mhsspt_nan_state_kept",
        _nan_refused_state_kept(lambda: _mhsspt(), _feed1, r"non-finite|NaN|finite"),
        r"",
        (),
    ),
    ("obs_wrong_u_shape", lambda d: _obs_step(d, np.zeros((1, 3)), np.zeros((1, 2))), r"must have shape", ()),
    ("obs_wrong_y_shape", lambda d: _obs_step(d, np.zeros((1, 1)), np.zeros((1, 5))), r"must have shape", ()),
    ("obs_3d_input", lambda d: _obs_step(d, np.zeros((1, 1, 1)), np.zeros((1, 2))), r"must have shape", ()),
    ("glrt_wrong_shape", lambda d: _proc_step(_glrt(), np.zeros((1, 3))), r"must have shape", ()),
    ("hold_wrong_shape", lambda d: _proc_step(_hold_c(), np.zeros((1, 1))), r"must have shape", ()),
    ("mhsspt_wrong_shape", lambda d: _proc_step(_mhsspt(), np.zeros((1, 2))), r"must have shape", ()),
    (
        "hold_threshold_count_3_for_2",
        _call(lambda: __import__("fdikit.detect", fromlist=["Hold"]).Hold(["a", "b"], [1.0, 2.0, 3.0])),
        r"threshold",
        (),
    ),
    (
        "hold_threshold_count_2_for_3",
        _call(lambda: __import__("fdikit.detect", fromlist=["Hold"]).Hold(["a", "b", "c"], [1.0, 2.0])),
        r"threshold",
        (),
    ),
    (
        "hold_threshold_matrix",
        _call(lambda: __import__("fdikit.detect", fromlist=["Hold"]).Hold(["a", "b"], np.ones((2, 2)))),
        r"threshold",
        (),
    ),
    (
        "hold_z_zero",
        _call(lambda: __import__("fdikit.detect", fromlist=["Hold"]).Hold(["a"], 1.0, Z=0)),
        r"Z",
        (),
    ),
    (
        "hold_threshold_nan",
        _call(lambda: __import__("fdikit.detect", fromlist=["Hold"]).Hold(["a"], float("nan"))),
        r"threshold",
        (),
    ),
    (
        "glrt_w_zero",
        _call(lambda: __import__("fdikit.detect", fromlist=["GLRT"]).GLRT(["a"], 0.0, 1.0, W=0)),
        r"W",
        (),
    ),
    (
        "glrt_negative_variance",
        _call(lambda: __import__("fdikit.detect", fromlist=["GLRT"]).GLRT(["a"], 0.0, -1.0)),
        r"sigma|variance",
        (),
    ),
    ("signals_2d_time", _sig(np.zeros((2, 2)), np.zeros((4, 1)), ["a"]), r"must be 1-D", ()),
    (
        "signals_nan_time",
        _sig(np.array([0.0, np.nan]), np.zeros((2, 1)), ["a"]),
        r"non-finite value at sample 1",
        (),
    ),
    (
        "signals_time_back",
        _sig(np.array([0.0, 1.0, 0.5]), np.zeros((3, 1)), ["a"]),
        r"not strictly increasing at sample 2",
        (),
    ),
    (
        "signals_shape_mismatch",
        _sig(np.arange(3.0), np.zeros((4, 1)), ["a"]),
        r"4 samples along time but t has 3",
        (),
    ),
    ("signals_names_mismatch", _sig(np.arange(3.0), np.zeros((3, 2)), ["a"]), r"2 channels but 1 names", ()),
    (
        "signals_duplicate_names",
        _sig(np.arange(3.0), np.zeros((3, 2)), ["a", "a"]),
        r"duplicated channel names",
        (),
    ),
    (
        "signals_units_count",
        _sig(np.arange(3.0), np.zeros((3, 1)), ["a"], ["m", "s"]),
        r"2 units for 1 channels",
        (),
    ),
    (
        "signals_nan_value",
        _sig(np.arange(3.0), np.array([[0.0], [np.nan], [0.0]]), ["a"]),
        r"channel 'a' has a non-finite value \(nan\) at run 0, sample 1",
        (),
    ),
    ("signals_4d", _sig(np.arange(3.0), np.zeros((1, 1, 3, 1)), ["a"]), r"must have shape", ()),
    (
        "signals_bad_t0",
        _sig(np.arange(3.0), np.zeros((3, 1)), ["a"], t0=float("nan")),
        r"t0 must be finite",
        (),
    ),
    (
        "signals_unknown_channel",
        lambda d: __import__("fdikit").Signals(np.arange(3.0), np.zeros((3, 1)), ["a"])["b"],
        r"unknown channel 'b'",
        (),
    ),
    (
        "signals_run_out_of_range",
        lambda d: __import__("fdikit").Signals(np.arange(3.0), np.zeros((3, 1)), ["a"]).run(3),
        r"run 3 out of range",
        (),
    ),
    ("logsignals_valid_shape", _logsignals(valid=np.ones((2, 1), bool)), r"validity mask has shape", ()),
    (
        "logsignals_valid_on_nan",
        lambda d: __import__("fdikit.io", fromlist=["LogSignals"]).LogSignals(
            np.arange(3.0), np.array([[0.0], [np.nan], [1.0]]), ["a"], valid=np.ones((3, 1), bool)
        ),
        r"marked valid but is not finite at run 0, sample 1",
        (),
    ),
    ("resample_bad_method", _rtg(method="cubic"), r"unknown resampling method 'cubic'", ()),
    ("series_to_grid_no_signals", _stg(series={}), r"no signals requested", ()),
    ("series_to_grid_max_gap_0", _stg(max_gap=0), r"max_gap must be a positive", ()),
    ("series_to_grid_rate_negative", _stg(rate=-1.0), r"grid rate must be a positive", ()),
    ("series_to_grid_rate_text", _stg(rate="fast"), r"grid rate must be a positive", ()),
    ("series_to_grid_bad_span", _stg(span="all"), r"span must be 'common' or 'log'", ()),
    ("series_to_grid_bad_units", _stg(units="imperial"), r"units must be 'si' or a mapping", ()),
    (
        "series_to_grid_time_back",
        _stg(series={"x": (np.array([0.0, 2.0, 1.0]), np.zeros(3))}),
        r"goes backwards at sample 2",
        (),
    ),
    (
        "series_to_grid_huge_grid",
        _stg(series={"x": (np.array([0.0, 1e12]), np.zeros(2))}, rate=100.0),
        r"too large.*time_unit",
        (),
    ),
    ("gridder_rate_zero", _gridder(rate=0.0), r"rate must be a positive", ()),
    ("gridder_rate_text", _gridder(rate="x"), r"rate must be a positive", ()),
    ("gridder_no_signals", _gridder(signals=[]), r"non-empty list", ()),
    ("gridder_signal_string", _gridder(signals="SPEED.SPEED"), r"non-empty list", ()),
    ("gridder_unknown_message", _gridder(signals=["SPEDO.SPEED"]), r"no message 'SPEDO'", ()),
    ("gridder_unknown_signal", _gridder(signals=["SPEED.SPEEDO"]), r"has no signal 'SPEEDO'", ()),
    ("gridder_bad_method", _gridder(method="cubic"), r"unknown resampling method", ()),
    ("gridder_max_gap_negative", _gridder(max_gap=-1.0), r"max_gap must be", ()),
    (
        "gridder_time_back",
        _gridder_push([(1.0, 180, bytes(8)), (0.5, 180, bytes(8))]),
        r"time goes backwards",
        (),
    ),
    ("gridder_time_nan", _gridder_push([(float("nan"), 180, bytes(8))]), r"non-finite time", ()),
    (
        "gridder_two_buses",
        _gridder_push([(0.0, 180, bytes(8), "can0"), (0.1, 180, bytes(8), "can1")]),
        r"several buses",
        (),
    ),
    ("candump_garbage", _candump_line("hello world"), r"line 7 is not a frame", ()),
    ("candump_odd_hex", _candump_line("(1.0) can0 0B4#123"), r"odd number of hex digits", ()),
    ("candump_inf_time", _candump_line("(1e999) can0 0B4#00"), r"not finite", ()),
    ("candump_no_time", _candump_line("can0 0B4#00"), r"not a frame", ()),
    ("candump_bad_id", _candump_line("(1.0) can0 XYZ#00"), r"not a frame", ()),
    (
        "convert_units_unknown",
        _io(
            lambda: __import__("fdikit.io", fromlist=["convert_units"]).convert_units(
                [1.0], "furlong", "m", channel="d"
            )
        ),
        r"cannot convert channel 'd' from unit 'furlong'",
        (),
    ),
    ("read_log_bad_format", _read_log(format="xml"), r"unknown log format 'xml'", ()),
    ("read_log_bad_option", _read_log(strict=False), r"do not apply to a csv log", ()),
    ("read_log_bad_time_unit", _read_log(time_unit="h"), r"time_unit must be one of", ()),
    (
        "read_log_missing",
        _io(lambda: __import__("fdikit.io", fromlist=["read_log"]).read_log("/nonexistent/x.blf")),
        r"does not exist",
        (),
    ),
    ("read_log_no_dbc", lambda d: _blf_without_dbc(d), r"pass dbc=", ()),
    ("read_csv_bad_time_unit", _csv_call("t,x\n0,1\n", time_unit="minutes"), r"time_unit must be one of", ()),
    (
        "read_csv_ns_as_seconds_gridded",
        _csv_call("t,x\n1700000000000000000,1\n1700000000010000000,2\n", time_unit="s", rate=100.0),
        r"too large.*time_unit",
        (),
    ),
    (
        "read_csv_missing_file",
        _io(lambda: __import__("fdikit.io", fromlist=["read_csv"]).read_csv("/nonexistent.csv")),
        r"does not exist",
        (),
    ),
    (
        "read_csv_directory",
        lambda d: __import__("fdikit.io", fromlist=["read_csv"]).read_csv(d),
        r"is a directory",
        (),
    ),
    ("read_csv_unit_for_unknown", _csv_call("t,x\n0,1\n", units={"y": "m"}), r"unit given for 'y'", ()),
    (
        "read_csv_convert_impossible",
        _csv_call("t,x\n0,1\n", units={"x": "m"}, convert={"x": "rad"}),
        r"cannot convert channel 'x'",
        (),
    ),
    ("read_csv_unknown_column", _csv_call("t,x\n0,1\n", columns=["y"]), r"no column\(s\) \['y'\]", ()),
    ("read_csv_bad_encoding", _csv_call("t,x\n0,1\n", encoding="klingon"), r"unknown text encoding", ()),
    (
        "times_bad_unit",
        _io(
            lambda: __import__("fdikit.io", fromlist=["times_to_seconds"]).times_to_seconds(
                ["1"], "fortnight"
            )
        ),
        r"time_unit must be one of",
        (),
    ),
    (
        "times_empty",
        _io(lambda: __import__("fdikit.io", fromlist=["times_to_seconds"]).times_to_seconds([])),
        r"no values",
        (),
    ),
    ("invalid_reason_out_of_range", lambda d: _loaded().invalid_reason(99), r"sample 99 out of range", ()),
]


def _raise_nan(d):
    from fdikit.monitor import Monitor

    m = _mon(d)
    mon = Monitor(m.generators, m.processors, m.decision, on_invalid="raise")
    mon.reset(1)
    mon.step(0.0, {"force": 0.0, "pos1": np.nan, "pos2": 0.0})


def _bad_on_invalid(d):
    from fdikit.monitor import Monitor

    m = _mon(d)
    Monitor(m.generators, m.processors, on_invalid="ignore")


def _two_channel_signals():
    from fdikit import Signals

    return Signals(np.arange(5) * 0.01, np.zeros((5, 2)), ["force", "pos1"])


def _proc_missing(d):
    from fdikit.detect import GLRT
    from fdikit.monitor import Monitor

    m = _mon(d)
    Monitor(m.generators, [GLRT(["r:pos9"], 0.0, 1.0)])


def _decision_unknown(d):
    from fdikit.monitor import Decision, Monitor

    m = _mon(d)
    Monitor(m.generators, m.processors, Decision(["r:pos9:alarm"], 0.5, {}))


def _obs_step(d, u, y):
    g = _obs(d)
    g.reset(1)
    g.step(u, y)


def _proc_step(p, r):
    p.reset(1)
    p.step(r)


def _blf_without_dbc(d):
    from fdikit.io import read_log

    p = Path(d) / "x.blf"
    p.write_bytes(b"LOGG" + bytes(200))
    try:
        read_log(p, None, ["A.B"])
    finally:
        p.unlink()


def _loaded():
    from fdikit.io import series_to_grid

    return series_to_grid({"x": (np.arange(5.0), np.arange(5.0))}, {}, rate=1.0)


API = [pytest.param(fn, pat, id=name, marks=list(marks)) for name, fn, pat, marks in API_TABLE]


@pytest.mark.parametrize("fn, pattern", API)
def test_api_misuse(designed, tmp_path, fn, pattern):
    try:
        out = fn(designed)
    except (DataError, ConditionError) as exc:
        msg = str(exc)
        assert len(msg) >= 12 and re.search(pattern, msg, re.IGNORECASE | re.DOTALL), (
            f"{msg!r} does not match {pattern!r}"
        )
        return
    # the NaN-refusal cases assert inside and return nothing
    assert pattern == "" and out is None, f"no error for a misuse; returned {out!r}"


# =====================================================================================
# the count
# =====================================================================================
CLASSES = {
    "artefacts (readers)": ARTEFACTS,
    "artefacts (monitor)": MONITOR + GAPS,
    "CLI paths": CLI + CLI_OK,
    "config semantics": CONFIG,
    "artifacts": ARTIFACTS + ARTIFACT_FILES,
    "API misuse": API,
}


def test_campaign_has_at_least_400_cases():
    counts = {k: len(v) for k, v in CLASSES.items()}
    assert all(n >= 20 for n in counts.values()), counts
    assert sum(counts.values()) >= 400, counts


# =====================================================================================
# hypothesis fuzz: CSV, candump, BLF, follow mode
# =====================================================================================
CELL = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.sampled_from(["", "nan", "inf", "-inf", "1e300", "0", "-0", "1e-320", " 3 ", "NA", "1e400"]),
    st.integers(-(10**20), 10**20).map(str),
)
BAD_CELL = st.sampled_from(["abc", "1,5", "0x10", "--1", "1e", "\u00b5"])


@st.composite
def csv_texts(draw):
    ncol = draw(st.integers(1, 4))
    header = ["t", "x", "y", "z"][:ncol]
    if draw(st.integers(0, 4)) == 0:
        header = draw(st.lists(st.sampled_from(["t", "x", "y", "z", "t", ""]), min_size=ncol, max_size=ncol))
    nrow = draw(st.integers(0, 30))
    t0 = draw(st.sampled_from([0.0, -5.0, 1.7e9, 1.7e12, 1.7e18]))
    dt = draw(st.sampled_from([0.01, 0.5, 1.0, 1e7]))
    rows = []
    for k in range(nrow):
        r = [draw(CELL) for _ in range(ncol)]
        if draw(st.integers(0, 49)) == 0:
            r[draw(st.integers(0, ncol - 1))] = draw(BAD_CELL)
        if header[0] == "t" and draw(st.integers(0, 299)):
            r[0] = (
                repr(t0 + k * dt + draw(st.sampled_from([0.0, 0.0, 0.0, 1e-4, -1e-4])))
                if t0 < 1e15
                else str(int(t0) + k * int(dt))
            )
        if draw(st.integers(0, 49)) == 0:
            r = r[:-1] if len(r) > 1 else [*r, "1"]
        rows.append(r)
    sep = "," if draw(st.integers(0, 9)) else ";"
    text = "\n".join([sep.join(header)] + [sep.join(r) for r in rows]) + "\n"
    if draw(st.integers(0, 4)) == 0:
        text = text[: draw(st.integers(0, len(text)))]
    if draw(st.integers(0, 9)) == 0:
        text = "\ufeff" + text
    return text


@FUZZ
@given(text=csv_texts(), rate=st.sampled_from([None, 10.0, 100.0]), table=st.booleans())
def test_fuzz_csv_reader(tmp_path_factory, text, rate, table):
    from fdikit.io import read_csv, read_log

    p = tmp_path_factory.mktemp("fz") / "f.csv"
    p.write_text(text, encoding="utf-8")
    try:
        s = read_log(p, rate=rate) if table else read_csv(p, rate=rate)
    except DataError as exc:
        assert len(str(exc)) >= 12
        return
    check_log(s)
    assert s.n_samples <= 50_000_000


_HEX = "0123456789ABCDEF"


@st.composite
def candump_lines(draw):
    kind = draw(st.integers(0, 9))
    if kind == 0:
        return draw(st.text(max_size=40))
    t = draw(st.one_of(st.floats(0, 2e9), st.sampled_from([float("inf"), -1.0, 1e308])))
    fid = draw(st.sampled_from(["0B4", "0AA", "7FF", "1FFFFFFF", "G12", ""]))
    data = "".join(draw(st.lists(st.sampled_from(_HEX), max_size=17)))
    flag = draw(st.sampled_from(["", " R", " T", " X"]))
    return f"({t:.6f}) can0 {fid}#{data}{flag}"


@FUZZ
@given(lines=st.lists(candump_lines(), max_size=30))
def test_fuzz_candump_parser_and_reader(tmp_path_factory, lines):
    from fdikit.io import parse_candump_line, read_log

    for i, ln in enumerate(lines):
        try:
            out = parse_candump_line(ln, i + 1)
        except DataError as exc:
            assert f"line {i + 1}" in str(exc)
            continue
        if out is not None:
            t, _bus, fid, payload = out
            assert math.isfinite(t) and isinstance(payload, bytes) and 0 <= fid < 2**32
    p = tmp_path_factory.mktemp("cd") / "f.log"
    p.write_text("\n".join(lines) + "\n")
    try:
        s = read_log(p, _db(), ["SPEED.SPEED", "WHEELS.FL"], rate=10.0)
    except DataError as exc:
        assert len(str(exc)) >= 12
        return
    check_log(s)


@st.composite
def frames(draw):
    n = draw(st.integers(1, 40))
    t = np.cumsum(draw(st.lists(st.sampled_from([0.0, 0.001, 0.01, 0.1, 2.0]), min_size=n, max_size=n)))
    out = []
    for k in range(n):
        fid = draw(st.sampled_from([0xB4, 0xAA, 0x123]))
        dlc = draw(st.integers(0, 8))
        out.append(
            (float(1.7e9 + t[k]), fid, bytes(draw(st.lists(st.integers(0, 255), min_size=dlc, max_size=dlc))))
        )
    return out


@FUZZ
@given(
    fr=frames(),
    corrupt=st.sampled_from(["none", "truncate", "flip", "zero_tail", "append"]),
    seed=st.integers(0, 2**16),
)
def test_fuzz_blf_reader(tmp_path_factory, fr, corrupt, seed):
    import can

    from fdikit.io import read_log

    p = tmp_path_factory.mktemp("blf") / "f.blf"
    with can.BLFWriter(str(p)) as w:
        for t, fid, data in fr:
            w.on_message_received(
                can.Message(timestamp=t, arbitration_id=fid, data=data, is_extended_id=False)
            )
    raw = bytearray(p.read_bytes())
    r = np.random.default_rng(seed)
    if corrupt == "truncate":
        raw = raw[: int(r.integers(0, len(raw)))]
    elif corrupt == "flip":
        for _ in range(4):
            raw[int(r.integers(0, len(raw)))] ^= 0xFF
    elif corrupt == "zero_tail":
        k = int(r.integers(0, len(raw)))
        raw[k:] = bytes(len(raw) - k)
    elif corrupt == "append":
        raw += bytes(r.integers(0, 256, 50, dtype=np.uint8))
    p.write_bytes(bytes(raw))
    try:
        s = read_log(p, _db(), ["SPEED.SPEED", "WHEELS.FL"], rate=20.0)
    except DataError as exc:
        assert len(str(exc)) >= 12
        return
    check_log(s)
    if corrupt == "none":  # every frame accounted for
        n_speed = sum(1 for f in fr if f[1] == 0xB4)
        q = s.info["SPEED.SPEED"]
        assert q.n_samples + q.n_duplicates + q.n_conflicts == n_speed
        assert s.t0 == pytest.approx(fr[0][0], abs=1e-6)


@st.composite
def follow_lines(draw, header="time,F,P1,P2"):
    n = draw(st.integers(1, 40))
    lines = [header] if draw(st.integers(0, 9)) else [draw(st.sampled_from(["", "t,F", "time;F;P1;P2"]))]
    t = 0.0
    for _ in range(n):
        kind = draw(st.integers(0, 12))
        t += draw(st.sampled_from([0.01, 0.01, 0.01, 0.0, -0.02, 0.5]))
        if kind == 0:
            lines.append(draw(st.text(max_size=30)).replace("\n", " "))
        elif kind == 1:
            lines.append(f"{t:.2f},1.0")
        else:
            cells = [
                draw(st.sampled_from(["0.0", "0.001", "nan", "inf", "", "abc", "1e300"])) for _ in range(3)
            ]
            if kind > 4:
                cells = ["0.0", "0.0", "0.0"]
            lines.append(f"{t:.2f}," + ",".join(cells))
    return lines


@FUZZ
@given(lines=follow_lines())
def test_fuzz_follow_csv(workdir, lines):
    p = workdir / "fz_follow.csv"
    p.write_text("\n".join(lines) + "\n")
    rc, out, err = run_cli(["monitor", p, "--config", workdir / "monitor.toml", "--follow"])
    if rc != 0:
        assert rc == 2 and "error" in err and len(err) > 20
        return
    for rec in _events(out):
        for v in rec.values():
            if isinstance(v, float):
                assert math.isfinite(v)


@FUZZ
@given(lines=st.lists(candump_lines(), max_size=60), rate=st.sampled_from([10.0, 100.0]))
def test_fuzz_follow_candump_through_the_gridder_into_the_monitor(designed, lines, rate):
    """candump lines (random, garbled) -> parse -> FrameGridder -> Monitor.step: each bad line is a
    DataError for that line only; the monitor's outputs stay finite; a gap or bad frame arrives as
    a NaN sample with a reason, which the monitor flags."""
    from fdikit.io import FrameGridder, parse_candump_line

    mon = build_monitor_from(designed)
    mon.reset(1)
    g = FrameGridder(_db(), ["SPEED.SPEED", "WHEELS.FL", "WHEELS.FR"], rate)
    base = [
        (f"({1.7e9 + 0.01 * k:.6f}) can0 {fid}#{(k * 37 % 65535):04X}{(k * 11 % 65535):04X}0000000{k % 10}")
        for k in range(40)
        for fid in ("0B4", "0AA")
    ]
    feed = base[:30] + lines + base[30:]
    n_steps = 0
    last = None

    def step(samples):
        nonlocal n_steps
        for t, vals, why in samples:
            assert t > (last if last is not None else -1.0)
            sample = {
                "force": vals["SPEED.SPEED"],
                "pos1": vals["WHEELS.FL"] * 1e-3,
                "pos2": vals["WHEELS.FR"] * 1e-3,
            }
            r, s, _ = mon.step(t, sample)
            assert np.all(np.isfinite(r)) and np.all(np.isfinite(s))
            if why is not None:
                assert mon.last_invalid is not None, f"the gridder's invalid sample was not flagged: {why}"
            n_steps += 1

    for i, ln in enumerate(feed):
        try:
            fr = parse_candump_line(ln, i + 1)
        except DataError:
            continue
        if fr is None:
            continue
        try:
            step(g.push(fr[0], fr[2], fr[3], fr[1]))
        except DataError as exc:
            assert "frame" in str(exc) or "bus" in str(exc)
    step(g.flush())
    assert g.t0 is None or math.isfinite(g.t0)
