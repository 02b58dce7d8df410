import numpy as np
import pytest

from fdikit import DataError, Signals


def test_shapes_and_access():
    t = np.arange(5) * 0.1
    s = Signals(t, np.arange(10.0).reshape(5, 2), ["a", "b"], ["m", "s"])
    assert s.values.shape == (1, 5, 2) and s.runs == 1 and len(s) == 5
    np.testing.assert_array_equal(s["b"][0], [1, 3, 5, 7, 9])
    assert s.select(["b"]).names == ["b"] and s.select(["b"]).units == ["s"]
    assert s.window(0.05, 0.35).n_samples == 3
    assert abs(s.dt - 0.1) < 1e-15


def test_pandas_round_trip():
    rng = np.random.default_rng(0)
    s = Signals(np.linspace(0, 1, 7), rng.normal(size=(7, 3)), ["x", "y", "z"])
    back = Signals.from_pandas(s.to_pandas())
    assert back.equals(s)
    many = Signals(np.linspace(0, 1, 7), rng.normal(size=(2, 7, 3)), ["x", "y", "z"])
    df = many.to_pandas()
    assert df.shape == (14, 3)
    np.testing.assert_array_equal(df.loc[1].to_numpy(), many.values[1])


@pytest.mark.parametrize(
    "t, values, names, match",
    [
        ([0, 1, 1], np.zeros((3, 1)), ["a"], "not strictly increasing at sample 2"),
        ([0, 2, 1], np.zeros((3, 1)), ["a"], "not strictly increasing at sample 2"),
        ([0, np.nan, 2], np.zeros((3, 1)), ["a"], "non-finite value at sample 1"),
        ([0, 1, 2], np.zeros((3, 2)), ["a"], "2 channels but 1 names"),
        ([0, 1, 2], np.zeros((4, 1)), ["a"], "4 samples along time but t has 3"),
        ([0, 1, 2], np.zeros((3, 2)), ["a", "a"], "duplicated channel names"),
        ([0, 1, 2], np.zeros((2, 2, 3, 1)), ["a"], "must have shape"),
        ([[0, 1, 2]], np.zeros((3, 1)), ["a"], "must be 1-D"),
    ],
)
def test_bad_input_is_named(t, values, names, match):
    with pytest.raises(DataError, match=match):
        Signals(t, values, names)


def test_nan_names_channel_run_and_sample():
    v = np.zeros((2, 4, 2))
    v[1, 3, 1] = np.inf
    with pytest.raises(DataError, match=r"channel 'b' .* run 1, sample 3"):
        Signals(np.arange(4.0), v, ["a", "b"])
    s = Signals(np.arange(4.0), v, ["a", "b"], check=False)
    assert s.runs == 2


def test_unknown_channel():
    s = Signals(np.arange(3.0), np.zeros((3, 1)), ["a"])
    with pytest.raises(DataError, match="unknown channel 'q'"):
        s["q"]
