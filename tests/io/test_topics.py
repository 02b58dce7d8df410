"""Folders of per-topic CSVs and the causal multi-rate grid (issue 28): round trip at 19, 2.9 and
2.5 Hz, absolute clocks aligned across files, the age channel against brute force, linear marked
non-causal, and the property that the default grid never uses a message from the future."""

from __future__ import annotations

import random
from pathlib import Path

import numpy as np
import pytest

from fdikit.errors import DataError
from fdikit.io import read_log, read_topic_folder, topics_to_grid
from fdikit.io.formats import MultiRateSignals, detect_format

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

RATES = {"odom": 19.0, "battery": 2.9, "gps": 2.5}


def write_folder(d: Path, *, clock_ns: int | None = None, seed: int = 0) -> dict:
    """Three topic files at 19, 2.9 and 2.5 Hz with jittered times; returns the truth."""
    rng = np.random.default_rng(seed)
    d.mkdir(parents=True, exist_ok=True)
    truth = {}
    for k, (topic, hz) in enumerate(RATES.items()):
        n = int(10 * hz)
        t = np.round(np.arange(n) / hz + rng.uniform(0, 0.004, n) + 0.01 * k, 6)
        v = np.round(rng.normal(size=(n, 2)), 6)
        truth[topic] = (t, v)
        cols = ["timestamp", "a [m/s]", "b", "frame"]
        lines = [",".join(cols)]
        for tt, (x, y) in zip(t, v):
            ts = f"{tt:.6f}" if clock_ns is None else str(clock_ns + round(tt * 1e9))
            lines.append(f"{ts},{float(x)!r},{float(y)!r},base_link")
        (d / f"{topic}.csv").write_text("\n".join(lines) + "\n")
    return truth


def _brute_hold(t, v, grid):
    out = np.full(grid.shape, np.nan)
    age = np.full(grid.shape, np.nan)
    for k, g in enumerate(grid):
        before = np.flatnonzero(t <= g + 1e-9)  # a sample 1 ns after g (rounding) is at g
        if before.size:
            out[k] = v[before[-1]]
            age[k] = max(g - t[before[-1]], 0.0)
    return out, age


def test_round_trip_hold_and_age(tmp_path):
    truth = write_folder(tmp_path / "run")
    s = read_topic_folder(tmp_path / "run", rate=20.0)
    assert isinstance(s, MultiRateSignals) and s.causal and s.method == "previous"
    assert s.names == ["battery.a", "battery.b", "gps.a", "gps.b", "odom.a", "odom.b",
                       "battery.__age__", "gps.__age__", "odom.__age__"]
    assert s.units[:2] == ["m/s", ""] and s.units[-1] == "s"
    assert s.t0 == 0.0 and s.time_origin is None
    for topic, (t, v) in truth.items():
        for j, f in enumerate("ab"):
            hold, age = _brute_hold(t, v[:, j], s.t)
            np.testing.assert_array_equal(s[f"{topic}.{f}"][0], hold)
            np.testing.assert_allclose(s.age(topic), age, atol=1e-12)
    assert s.valid.all()
    assert detect_format(tmp_path / "run") == "topics"
    r = read_log(tmp_path / "run", signals=["gps", "odom.b"], rate=20.0)
    assert r.names == ["gps.a", "gps.b", "odom.b", "gps.__age__", "odom.__age__"]


def test_absolute_clocks_are_aligned_across_files(tmp_path):
    write_folder(tmp_path / "rel")
    rel = read_topic_folder(tmp_path / "rel", rate=20.0)
    clock = 1_700_000_000_123_000_000
    write_folder(tmp_path / "abs", clock_ns=clock)
    s = read_topic_folder(tmp_path / "abs", rate=20.0)
    # the origin is the earliest first time over all files, exact; the topics stay aligned
    first = min(int(p.read_text().splitlines()[1].split(",")[0]) for p in (tmp_path / "abs").glob("*.csv"))
    assert s.time_origin.exponent == 9 and s.time_origin.ticks == first
    np.testing.assert_allclose(s.t + s.t0 - clock / 1e9, rel.t, atol=1e-6)
    np.testing.assert_array_equal(s.values[0, :, :6], rel.values[0, :, :6])


def test_linear_max_age_and_options(tmp_path):
    write_folder(tmp_path / "run")
    lin = read_topic_folder(tmp_path / "run", ["gps.a"], rate=20.0, method="linear")
    assert lin.causal is False and lin.method == "linear"
    assert lin.select(["gps.a"]).causal is False
    st_ = read_topic_folder(tmp_path / "run", ["gps.a"], rate=20.0, max_age=0.3)
    np.testing.assert_array_equal(st_.valid[0, :, 0], st_.age("gps") <= 0.3)
    noage = read_topic_folder(tmp_path / "run", ["gps.a"], rate=20.0, age=False)
    assert noage.names == ["gps.a"]
    with pytest.raises(DataError, match="max_age applies to method='previous'"):
        read_topic_folder(tmp_path / "run", rate=20.0, method="linear", max_age=1.0)


def test_bad_folders(tmp_path):
    with pytest.raises(DataError, match="does not exist"):
        read_topic_folder(tmp_path / "none")
    (tmp_path / "empty").mkdir()
    with pytest.raises(DataError, match="no file matching"):
        read_topic_folder(tmp_path / "empty")
    write_folder(tmp_path / "run")
    with pytest.raises(DataError, match=r"no topic \['imu'\]; topics: \['battery', 'gps', 'odom'\]"):
        read_topic_folder(tmp_path / "run", ["imu.x"])
    with pytest.raises(DataError, match=r"no channel or topic 'gps.frame'"):
        read_topic_folder(tmp_path / "run", ["gps.frame"])  # a text column is not a channel
    with pytest.raises(DataError, match="no time column 'stamp'"):
        read_topic_folder(tmp_path / "run", time="stamp")
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "a.csv").write_text("t,x\n0,1\n0.1,2\n0.2\n")
    with pytest.raises(DataError, match=r"topic file 'a.csv' line 4 has 1 fields"):
        read_topic_folder(bad)
    (bad / "a.csv").write_text("t,x\n0,1\n0.1,oops\n0.2,3\n")
    with pytest.raises(DataError, match=r"'a.csv' line 3, column 'x': 'oops' is not a number"):
        read_topic_folder(bad)
    (bad / "a.csv").write_text("t,x\n0,1\n0.2,2\n0.1,3\n")
    with pytest.raises(DataError, match="goes backwards"):
        read_topic_folder(bad)
    (bad / "a.csv").write_text("t,x\n0,1\n0.1,2\n")
    (bad / "b.csv").write_text("t,x\n1700000000.0,1\n1700000000.1,2\n")
    with pytest.raises(DataError, match="mixes absolute clocks"):
        read_topic_folder(bad)


TEXT_OPS = ["truncate", "corrupt-char", "swap-lines", "drop-line", "duplicate-line"]


@pytest.mark.parametrize("op", TEXT_OPS)
@pytest.mark.parametrize("seed", range(4))
def test_fuzzed_topic_file(tmp_path, op, seed):
    write_folder(tmp_path / "run")
    p = tmp_path / "run" / "odom.csv"
    text = p.read_text()
    r = random.Random(seed)
    lines = text.splitlines(keepends=True)
    i = r.randrange(1, len(lines) - 2)
    if op == "truncate":
        text = text[: r.randrange(1, len(text))]
    elif op == "corrupt-char":
        k = r.randrange(len(lines[i]) - 1)
        lines[i] = lines[i][:k] + r.choice("0123456789x.,-e \t\"") + lines[i][k + 1:]
        text = "".join(lines)
    elif op == "swap-lines":
        lines[i], lines[i + 1] = lines[i + 1], lines[i]
        text = "".join(lines)
    elif op == "drop-line":
        del lines[i]
        text = "".join(lines)
    else:
        lines.insert(i, lines[i])
        text = "".join(lines)
    p.write_text(text)
    try:
        out = read_topic_folder(tmp_path / "run", rate=20.0)
    except DataError as exc:
        assert "'odom.csv'" in str(exc) or "odom" in str(exc), str(exc)
        return
    np.testing.assert_array_equal(out.valid, np.isfinite(out.values))


# ------------------------------------------------------------------ the causal property
@st.composite
def _topics_and_cut(draw):
    n_topics = draw(st.integers(1, 3))
    topics = {}
    for k in range(n_topics):
        ticks = sorted(set(draw(st.lists(st.integers(0, 3000), min_size=1, max_size=40))))
        t = np.array(ticks) / 1000.0  # ms lattice
        v = np.array(draw(st.lists(st.one_of(st.floats(-1e3, 1e3), st.just(float("nan"))),
                                   min_size=len(t), max_size=len(t))))
        topics[f"top{k}"] = (t, v)
    cut = draw(st.integers(0, 3000)) / 1000.0 + 0.0005  # off the lattice and off the grid
    shift = draw(st.sampled_from([0.001, 0.0371, 0.5, 7.0]))
    rate = draw(st.sampled_from([10.0, 19.0, 100.0]))
    max_age = draw(st.sampled_from([None, 0.05, 0.3]))
    return topics, cut, shift, rate, max_age


def _grid(topics, rate, max_age):
    spec = {tp: (t, {f"{tp}.v": v}) for tp, (t, v) in topics.items()}
    return topics_to_grid(spec, {}, rate, max_age=max_age)


@settings(max_examples=80, deadline=None, derandomize=True, database=None)
@given(_topics_and_cut())
def test_hypothesis_default_grid_never_uses_the_future(case):
    topics, cut, shift, rate, max_age = case
    try:
        a = _grid(topics, rate, max_age)
    except DataError:
        return  # e.g. no common span
    later = {tp: (np.where(t > cut, t + shift, t), v) for tp, (t, v) in topics.items()}
    b = _grid(later, rate, max_age)
    assert a.causal and b.causal
    ka, kb = a.t < cut, b.t < cut
    assert ka.sum() == kb.sum()
    n = int(ka.sum())
    np.testing.assert_array_equal(a.t[:n], b.t[:n])
    np.testing.assert_array_equal(a.values[:, :n], b.values[:, :n])
    np.testing.assert_array_equal(a.valid[:, :n], b.valid[:, :n])
    # and the age channel is the brute-force age
    for tp, (t, v) in topics.items():
        hold, age = _brute_hold(t, v, a.t)
        np.testing.assert_allclose(a.age(tp), age, atol=1e-12)
        ok = a.valid[0, :, a.names.index(f"{tp}.v")]
        np.testing.assert_array_equal(a[f"{tp}.v"][0][ok], hold[ok])


def test_linear_does_use_the_future():
    """The counter-example: linear interpolation changes before the cut, hence causal=False."""
    topics = {"x": (np.array([0.0, 1.0, 2.0]), np.array([0.0, 1.0, 2.0]))}
    spec = {"x": (topics["x"][0], {"x.v": topics["x"][1]})}
    a = topics_to_grid(spec, {}, 10.0, method="linear")
    later = {"x": (np.array([0.0, 1.0, 2.5]), {"x.v": np.array([0.0, 1.0, 2.0])})}
    b = topics_to_grid(later, {}, 10.0, method="linear", max_gap=10.0)
    assert not a.causal and not b.causal
    assert a["x.v"][0][15] != b["x.v"][0][15]  # t = 1.5 < the moved sample at 2.0


@pytest.mark.parametrize("clock", ["relative", "ns", "decimal"])
def test_fast_parser_equals_the_exact_path(tmp_path, monkeypatch, clock):
    """pyarrow's parser (fast path) and the line-by-line path give the same bits."""
    from fdikit.io.formats import topics as topics_mod

    write_folder(tmp_path / "run", clock_ns=None if clock == "relative" else 1_700_000_000_123_456_789)
    if clock == "decimal":
        (tmp_path / "run" / "gps.csv").write_text(
            "timestamp,a,b\n1700000000.123456789,1.5,\n1700000000.5234567891,,2\n1700000000.9,nan,3e-3\n")
    elif clock == "relative":
        (tmp_path / "run" / "gps.csv").write_text("timestamp,a,b\n0.0,1.5,\n0.4,,2\n0.8,nan,3e-3\n1.2,4,5\n")
    fast = read_topic_folder(tmp_path / "run", rate=20.0)
    monkeypatch.setattr(topics_mod, "_read_fast", lambda *a, **k: None)
    slow = read_topic_folder(tmp_path / "run", rate=20.0)
    assert fast.names == slow.names and fast.units == slow.units
    assert fast.time_origin == slow.time_origin
    np.testing.assert_array_equal(fast.t, slow.t)
    np.testing.assert_array_equal(fast.values, slow.values)
    np.testing.assert_array_equal(fast.valid, slow.valid)
    assert fast.info == slow.info
