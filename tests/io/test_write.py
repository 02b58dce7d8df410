"""fdikit.io.write: CSV and Parquet written from Signals read back identically by the readers."""

from __future__ import annotations

import numpy as np
import pytest

from fdikit import Signals
from fdikit.errors import DataError
from fdikit.io import read_csv, read_log, read_parquet
from fdikit.io.write import write_csv, write_parquet


@pytest.fixture
def sig():
    rng = np.random.default_rng(3)
    t = np.round(np.arange(500) * 0.01, 10) + 0.123456789
    v = rng.normal(0, 1, (2, 500, 3)) * np.array([1e-9, 1.0, 1e7])
    v[0, 17, 1] = np.nan
    v[0, 40, 2] = np.inf
    return Signals(t, v, ["tiny", "unit", "huge"], ["m", "rad/s", "Pa"], check=False)


def test_csv_round_trip_is_exact(tmp_path, sig):
    p = write_csv(sig, tmp_path / "log.csv")
    r = read_csv(p)
    assert r.names == sig.names and np.array_equal(r.t, sig.t)
    assert np.array_equal(r.values, sig.values[:1], equal_nan=True)  # repr floats: bit for bit
    assert not r.valid[0, 17, 1] and not r.valid[0, 40, 2] and r.valid[0, 18].all()
    r1 = read_csv(write_csv(sig, tmp_path / "run1.csv", run=1, time="time"), time="time")
    assert np.array_equal(r1.values[0], sig.values[1])


def _same_on_the_grid(r, sig):
    """read_log puts a table on a uniform grid: the same times and values (to rounding), the bad
    samples flagged and never filled (the grid reader also flags their neighbours' interpolants)."""
    assert r.names == sig.names and np.allclose(r.t, sig.t, rtol=0, atol=1e-9)
    bad = ~np.isfinite(sig.values[0])
    assert not r.valid[0][bad].any() and not np.isfinite(r.values[0][bad]).any()
    ok = r.valid[0]
    assert ok.sum() >= ok.size - 3 * bad.sum()
    assert np.allclose(r.values[0][ok], sig.values[0][ok], rtol=1e-9, atol=0)


def test_csv_through_read_log_flags_the_bad_samples(tmp_path, sig):
    _same_on_the_grid(read_log(write_csv(sig, tmp_path / "log.csv")), sig)


def test_parquet_round_trip_keeps_values_and_units(tmp_path, sig):
    p = write_parquet(sig, tmp_path / "log.parquet")
    for r in (read_parquet(p), read_log(p)):
        assert r.units == sig.units
        _same_on_the_grid(r, sig)


def test_writers_name_bad_input(tmp_path, sig):
    with pytest.raises(DataError, match="must end in .csv"):
        write_csv(sig, tmp_path / "log.txt")
    with pytest.raises(DataError, match="does not exist"):
        write_parquet(sig, tmp_path / "no" / "log.parquet")
    with pytest.raises(DataError, match="also a channel name"):
        write_csv(sig, tmp_path / "log.csv", time="unit")
    with pytest.raises(DataError, match="run 5 out of range"):
        write_csv(sig, tmp_path / "log.csv", run=5)
    bad = Signals(sig.t, sig.values[:, :, :1], ["a,b"], check=False)
    with pytest.raises(DataError, match="commas"):
        write_csv(bad, tmp_path / "log.csv")
    assert not (tmp_path / "log.csv").exists()
