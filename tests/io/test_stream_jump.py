"""A garbled time stamp far in the future must not make the live gridder emit the whole interval.

Found by the candump fuzz test on a fresh CI machine: one line stamped ~1e8 s after the others
made ``FrameGridder`` emit a grid sample per 1/rate s of it (hours of work, a hang of the follow
mode). Such a frame is now refused as a corrupt clock, and the stream goes on.
"""

from __future__ import annotations

import cantools
import pytest

from fdikit.errors import DataError
from fdikit.io import FrameGridder

DBC = '''VERSION ""
BO_ 180 SPEED: 8 XXX
 SG_ SPEED : 47|16@0+ (0.01,0) [0|250] "km/h" XXX
'''


def _frame(kmh: float) -> bytes:
    return (int(kmh * 100) << 8).to_bytes(8, "big")


def test_far_future_frame_is_refused_and_the_stream_goes_on():
    g = FrameGridder(cantools.database.load_string(DBC, database_format="dbc"), ["SPEED.SPEED"], rate=100.0)
    out = []
    for k in range(30):
        out += g.push(1.7e9 + 0.01 * k, 180, _frame(10.0 + k))
    with pytest.raises(DataError, match=r"frame 30: .*more than max_jump = 3600 s.*corrupt clock"):
        g.push(1.7e9 + 1e8, 180, _frame(99.0))
    for k in range(30, 40):
        out += g.push(1.7e9 + 0.01 * k, 180, _frame(10.0 + k))
    out += g.flush()
    assert len(out) == 40
    # epoch time stamps carry ~1e-7 s of rounding, so the interpolated values ~1e-5 km/h
    assert [v["SPEED.SPEED"] for _, v, _ in out] == pytest.approx([10.0 + k for k in range(40)], abs=1e-4)
    assert all(why is None for _, _, why in out)


def test_a_long_real_gap_below_max_jump_is_gridded_as_invalid_samples():
    g = FrameGridder(cantools.database.load_string(DBC, database_format="dbc"), ["SPEED.SPEED"], rate=10.0,
                     max_jump=120.0)
    out = []
    for k in range(5):
        out += g.push(0.1 * k, 180, _frame(10.0))
    out += g.push(60.4, 180, _frame(10.0))  # a minute without frames: bridged, flagged
    out += g.flush()
    assert len(out) == 605
    assert sum(why is not None for _, _, why in out) > 590


@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan"), float("inf"), "x"])
def test_max_jump_validated(bad):
    with pytest.raises(DataError, match="max_jump"):
        FrameGridder(cantools.database.load_string(DBC, database_format="dbc"), ["SPEED.SPEED"], rate=10.0,
                     max_jump=bad)
