"""Silent API traps become clear errors or the right result (issues 26 item 8 and 30 items 4-5).

Each test fails on the code before the fix: a channel name split into characters, a threshold
design passed whole into an error message, a 5e-324 threshold on constant data, a masked
array's hidden values used, row numbers taken as time, a datetime clock taken as seconds, a
(T, 1) array's confusing refusal, a zero-rate design labelled empirical, '~' and '$HOME' in a
config written literally, a TOML with a byte-order mark refused.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from fdikit import DataError, Signals
from fdikit.base.paths import config_path
from fdikit.detect import Hold, design_threshold


def test_hold_takes_one_channel_name_as_one_channel():
    h = Hold("r:pos1", 0.5)
    assert h.input_names == ["r:pos1"] and h.output_names == ["r:pos1:alarm"]


def test_hold_takes_a_threshold_design_with_its_rule():
    g = np.random.default_rng(0).normal(size=(1, 4000, 2))
    d = design_threshold(g, 0.01, per="sample", Z=2, absolute=False)
    h = Hold(["a", "b"], d)
    np.testing.assert_array_equal(h.threshold, d.threshold)
    assert h.Z == 2 and h.absolute is False
    with pytest.raises(DataError, match="for 2 channels") as e:
        Hold(["a"], d)
    assert len(str(e.value)) < 300            # not the whole design
    with pytest.raises(DataError, match="Z = 3 differs"):
        Hold(["a", "b"], d, Z=3)


def test_hold_error_on_a_bad_threshold_is_short():
    with pytest.raises(DataError) as e:
        Hold(["a"], {"x": np.zeros(100_000)})
    assert len(str(e.value)) < 300


def test_constant_nominal_data_are_refused_by_name():
    with pytest.raises(DataError, match="'ch0' is constant"):
        design_threshold(np.zeros((400, 100)), 0.05)
    x = np.random.default_rng(1).normal(size=(1, 500, 3))
    x[0, :, 2] = 7.0
    with pytest.raises(DataError, match="'c' is constant"):
        design_threshold(x, 0.05, per="sample", channels=["a", "b", "c"])


def test_T_by_1_is_explained_as_T_runs_of_one_sample():
    x = np.random.default_rng(2).normal(size=500)
    with pytest.raises(DataError, match=r"500 runs of ONE sample each.*1-D array \(500,\)"):
        design_threshold(x[:, None], 0.05, per="sample")
    assert np.isfinite(design_threshold(x[:, None], 0.05).threshold)   # per run it is a valid layout


def test_masked_entries_are_never_used_silently():
    x = np.ma.masked_array(np.random.default_rng(3).normal(size=(1, 600)), mask=np.arange(600) == 7)
    with pytest.raises(DataError, match=r"1 masked entries .*index \[0, 7\]"):
        design_threshold(x, 0.05, per="sample")
    v = np.ma.masked_array(np.arange(6.0).reshape(3, 2), mask=[[0, 0], [1, 0], [0, 0]])
    with pytest.raises(DataError, match="masked"):
        Signals(np.arange(3.0), v, ["a", "b"])
    s = Signals(np.arange(3.0), v, ["a", "b"], check=False)
    assert np.isnan(s.values[0, 1, 0]) and s.values[0, 1, 1] == 3.0


def test_zero_rate_empirical_design_is_labelled_max():
    g = np.random.default_rng(4).normal(size=(1, 2000, 42))
    d = design_threshold(g, 0.01, per="sample", family_wise=True, method="empirical", min_events=0)
    assert set(d.method) == {"max"} and "no rate below" in d.note[0]
    d = design_threshold(g, 0.5, per="sample", method="empirical", min_events=0)
    assert set(d.method) == {"empirical"}


def test_from_pandas_finds_the_time_column_and_refuses_row_numbers():
    df = pd.DataFrame({"time": [0.0, 0.1, 0.25], "y": [1.0, 2.0, 3.0]})
    s = Signals.from_pandas(df)
    assert s.names == ["y"] and s.t.tolist() == [0.0, 0.1, 0.25]
    with pytest.raises(DataError, match="row numbers, not time"):
        Signals.from_pandas(pd.DataFrame({"a": [1.0, 2.0], "b": [3.0, 4.0]}))
    s = Signals.from_pandas(pd.DataFrame({"a": [1.0, 2.0]}), time="index")
    assert s.t.tolist() == [0.0, 1.0]


def test_from_pandas_datetime_and_nanosecond_clocks():
    ix = pd.to_datetime(["2026-01-01 00:00:00.000", "2026-01-01 00:00:00.010", "2026-01-01 00:00:00.020"])
    s = Signals.from_pandas(pd.DataFrame({"y": [1.0, 2.0, 3.0]}, index=ix))
    assert s.t.tolist() == [0.0, 0.01, 0.02] and s.t0 == 1767225600.0
    ns = np.array([1_700_000_000_000_000_000, 1_700_000_000_010_000_000], dtype=np.uint64)
    s = Signals.from_pandas(pd.DataFrame({"stamp": ns, "y": [1.0, 2.0]}))
    assert s.t.tolist() == [0.0, 0.01] and s.t0 == 1.7e9
    s = Signals.from_pandas(pd.DataFrame({"t": pd.Series(ix).dt.tz_localize("UTC"), "y": [1.0, 2.0, 3.0]}))
    assert s.t.tolist() == [0.0, 0.01, 0.02]


def test_from_pandas_round_trips_many_runs():
    s = Signals(np.arange(4) * 0.5, np.random.default_rng(5).normal(size=(3, 4, 2)), ["a", "b"])
    back = Signals.from_pandas(s.to_pandas())
    assert back.equals(s)


def test_config_paths_expand_home_and_variables(tmp_path, monkeypatch):
    monkeypatch.setenv("HOME", str(tmp_path))
    monkeypatch.setenv("FDIKIT_TEST_DATA", str(tmp_path / "data"))
    assert config_path("/elsewhere", "~/designs") == (tmp_path / "designs").resolve()
    assert config_path("/elsewhere", "$HOME/x") == (tmp_path / "x").resolve()
    assert (config_path("/elsewhere", "${FDIKIT_TEST_DATA}/car.dbc")
            == (tmp_path / "data" / "car.dbc").resolve())
    monkeypatch.delenv("FDIKIT_TEST_UNSET", raising=False)
    with pytest.raises(DataError, match="FDIKIT_TEST_UNSET is not set"):
        config_path("/elsewhere", "$FDIKIT_TEST_UNSET/x", where="[monitor].artifacts")


def test_monitor_config_artifacts_under_home_and_with_a_bom(tmp_path, monkeypatch):
    from pathlib import Path

    from fdikit.monitor.config import load_config

    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    example = Path(__file__).resolve().parents[1] / "examples" / "two-mass" / "monitor.toml"
    if not example.exists():
        pytest.skip("examples/ is not beside the tests")
    text = example.read_text().replace('artifacts = "designs"', 'artifacts = "~/x"')
    assert 'artifacts = "~/x"' in text
    cfg = tmp_path / "m.toml"
    cfg.write_bytes(b"\xef\xbb\xbf" + text.encode())      # a byte-order mark, as Windows editors write
    c = load_config(cfg)
    assert c.artifacts == (tmp_path / "home" / "x").resolve()


def test_svm_test_names_that_collide_are_refused():
    from sklearn.svm import SVC

    from fdikit.isolate import SVMIsolator

    rng = np.random.default_rng(6)
    X = np.r_[rng.normal(0, 1, (40, 2)), rng.normal(5, 1, (40, 2)), rng.normal(-5, 1, (40, 2))]
    lab = np.array(["nominal"] * 40 + ["fw_af"] * 40 + ["fwa_f"] * 40)
    with pytest.raises(DataError, match=r"'fw_af' and 'fwa_f' both give the test name 'S_fwaf'"):
        SVMIsolator(pipeline=SVC()).fit(X, lab)
    iso = SVMIsolator(pipeline=SVC(), test_names={"fw_af": "S_a", "fwa_f": "S_b"}).fit(X, lab)
    assert {"S_a", "S_b"} <= set(iso.outcomes(X))


def test_windowed_isolator_names_a_missing_nominal_label():
    from fdikit.isolate import WindowedIsolator

    r = np.random.default_rng(7).normal(size=(600, 3))
    lab = np.array(["NF"] * 300 + ["f1"] * 300)
    with pytest.raises(DataError, match="label 'nominal' .* not found"):
        WindowedIsolator(window=5, pfa=0.1).fit(r, lab)
