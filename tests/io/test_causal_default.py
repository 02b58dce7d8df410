"""Issue 28: every reader's default grid is causal (zero-order hold of the last sample).

A grid built by the default method never uses a sample from the future: shifting every message
after ``t`` by any amount leaves the grid before ``t`` unchanged. Linear interpolation (on request)
breaks that property, which shows the test can fail. A monitor config may ask for the linear grid
(``[log] resample = "linear"``); follow mode refuses it.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fdikit.errors import DataError
from fdikit.io import read_log
from fdikit.io.can import HOLD_TOL
from fdikit.io.formats import series_to_grid

DBC = '''VERSION ""
BO_ 180 SPEED: 8 XXX
 SG_ SPEED : 47|16@0+ (0.01,0) [0|250] "km/h" XXX
BO_ 37 KIN: 8 XXX
 SG_ YAW : 7|16@0- (0.01,0) [-300|300] "deg/s" XXX
'''


def _candump(path, frames):
    lines = []
    for t, fid, val in frames:
        raw = round(val * 100) & 0xFFFF
        data = (raw << 8).to_bytes(8, "big") if fid == 180 else (raw << 48).to_bytes(8, "big")
        lines.append(f"({t:.6f}) can0 {fid:03X}#{data.hex().upper()}")
    path.write_text("\n".join(lines) + "\n")
    return path


def _frames(rng, n=120):
    """Two messages at ~50 Hz and ~20 Hz with jitter (times in s, values in the signal's unit)."""
    out = []
    for fid, per in ((180, 0.02), (37, 0.05)):
        t = 100.0 + np.cumsum(per * (1 + 0.2 * rng.uniform(-1, 1, n)))
        out += [(float(a), fid, float(b)) for a, b in zip(t, rng.uniform(0, 100, n), strict=True)]
    return sorted(out)


@settings(max_examples=25, deadline=None, derandomize=True, database=None)
@given(st.integers(0, 10_000), st.floats(100.3, 102.0), st.sampled_from([0.004, 0.3, 5.0]))
def test_default_candump_grid_never_uses_the_future(tmp_path_factory, seed, cut, shift):
    d = tmp_path_factory.mktemp("causal")
    (d / "x.dbc").write_text(DBC)
    fr = _frames(np.random.default_rng(seed))
    later = [(t + shift if t > cut else t, fid, v) for t, fid, v in fr]
    sig = ["SPEED.SPEED", "KIN.YAW"]
    a = read_log(_candump(d / "a.log", fr), d / "x.dbc", sig, rate=100.0, span="log")
    b = read_log(_candump(d / "b.log", later), d / "x.dbc", sig, rate=100.0, span="log")
    k = a.t + a.t0 < cut - 1e-6
    n = int(k.sum())
    assert n > 10
    assert np.array_equal(a.t[:n], b.t[:n])
    assert np.array_equal(a.values[:, :n], b.values[:, :n], equal_nan=True)
    assert np.array_equal(a.valid[:, :n], b.valid[:, :n])


def test_linear_on_request_does_use_the_future(tmp_path):
    """The property the test above checks fails for the linear grid: the test can fail."""
    (tmp_path / "x.dbc").write_text(DBC)
    fr = _frames(np.random.default_rng(1))
    cut, shift = 101.0, 0.3
    later = [(t + shift if t > cut else t, fid, v) for t, fid, v in fr]
    sig = ["SPEED.SPEED", "KIN.YAW"]
    kw = dict(rate=100.0, span="log", method="linear")
    a = read_log(_candump(tmp_path / "a.log", fr), tmp_path / "x.dbc", sig, **kw)
    b = read_log(_candump(tmp_path / "b.log", later), tmp_path / "x.dbc", sig, **kw)
    n = int((a.t + a.t0 < cut - 1e-6).sum())
    assert not np.array_equal(a.values[:, :n], b.values[:, :n], equal_nan=True)


def test_csv_and_parquet_default_is_the_hold(tmp_path):
    import pandas as pd

    t = np.array([0.0, 0.1, 0.2, 0.3])
    df = pd.DataFrame({"t": t, "x": [0.0, 10.0, 20.0, 30.0]})
    df.to_csv(tmp_path / "a.csv", index=False)
    df.to_parquet(tmp_path / "a.parquet")
    for name in ("a.csv", "a.parquet"):
        s = read_log(tmp_path / name, signals=["x"], rate=20.0)
        assert s["x"][0].tolist() == [0.0, 0.0, 10.0, 10.0, 20.0, 20.0, 30.0], name
        lin = read_log(tmp_path / name, signals=["x"], rate=20.0, method="linear")
        assert lin["x"][0].tolist() == pytest.approx([0, 5, 10, 15, 20, 25, 30]), name


def test_a_sample_a_rounding_error_after_its_grid_time_is_held_from_it():
    # 0.35 as a grid time (35 / 100) and 35 * 0.01 as a sample time differ by 5.6e-17 s: the hold
    # must not lag a whole period for that (the causal rule is about information, not float rounding)
    t = np.arange(100) * 0.01
    late = np.flatnonzero(t > np.arange(100) / 100.0)
    assert late.size and np.all(t[late] - late / 100.0 < HOLD_TOL)
    s = series_to_grid({"x": (t, np.arange(100.0))}, {}, rate=100.0)
    assert s["x"][0].tolist() == list(range(100))


class _NoMonitor:
    def reset(self, n):
        pass


def test_follow_mode_refuses_a_linear_grid(tmp_path):
    from fdikit.monitor import LiveMonitor
    from fdikit.monitor.config import load_config

    (tmp_path / "x.dbc").write_text(DBC)
    text = """
[monitor]
name = "t"
[log]
dbc = "x.dbc"
rate = 50.0
resample = "%s"
[channels.v]
source = "SPEED.SPEED"
[[generators]]
artifact = "g"
[decision]
channels = ["v"]
"""
    (tmp_path / "m.toml").write_text(text % "linear")
    refused = r"resample = 'linear' .*not causal.*follow mode needs the causal hold"
    with pytest.raises(DataError, match=refused):
        LiveMonitor(load_config(tmp_path / "m.toml"), input="candump", monitor=_NoMonitor())
    (tmp_path / "bad.toml").write_text(text % "cubic")
    with pytest.raises(DataError, match=r"\[log\].resample must be 'previous' .* or 'linear'"):
        load_config(tmp_path / "bad.toml")
