"""A garbled time stamp far in the future must not make the live gridder emit the whole interval.

Found by the candump fuzz test on a fresh CI machine: one line stamped ~1e8 s after the others
made ``FrameGridder`` emit a grid sample per 1/rate s of it (hours of work, a hang of the follow
mode). Such a frame is now refused as a corrupt clock, and the stream goes on.
"""

from __future__ import annotations

import cantools
import numpy as np
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
    g = FrameGridder(cantools.database.load_string(DBC, database_format="dbc"), ["SPEED.SPEED"], rate=100.0,
                     method="linear")
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


def test_a_long_real_gap_below_max_jump_is_cut_from_the_grid():
    g = FrameGridder(cantools.database.load_string(DBC, database_format="dbc"), ["SPEED.SPEED"], rate=10.0,
                     max_jump=120.0)
    out = []
    for k in range(5):
        out += g.push(0.1 * k, 180, _frame(10.0))
    # a minute without a frame of any requested message: a gap the grid time jumps over (issue 27
    # item 4, the batch loader's rule), not 600 NaN samples
    out += g.push(60.4, 180, _frame(10.0))
    out += g.flush()
    # the causal default holds the last frame for max_gap = 3 source periods (0.5 .. 0.7 s), then
    # the stretch is cut
    assert [round(t, 6) for t, _, _ in out] == [0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 60.4]
    assert all(why is None for _, _, why in out)
    # with a second signal still sending, the gap of the first is gridded as invalid samples
    db = cantools.database.load_string(DBC + '''
BO_ 181 OTHER: 8 XXX
 SG_ X : 7|8@0+ (1,0) [0|255] "" XXX
''', database_format="dbc")
    g = FrameGridder(db, ["SPEED.SPEED", "OTHER.X"], rate=10.0, max_jump=120.0)
    out = []
    for k in range(60):
        if k < 5 or k > 50:
            out += g.push(0.1 * k, 180, _frame(10.0))
        out += g.push(0.1 * k + 0.05, 181, bytes(8))
    out += g.flush()
    assert 40 < sum(why is not None for _, _, why in out) < 50
    assert np.allclose(np.diff([o[0] for o in out]), 0.1)


@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan"), float("inf"), "x"])
def test_max_jump_validated(bad):
    with pytest.raises(DataError, match="max_jump"):
        FrameGridder(cantools.database.load_string(DBC, database_format="dbc"), ["SPEED.SPEED"], rate=10.0,
                     max_jump=bad)
