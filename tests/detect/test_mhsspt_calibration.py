"""Calibrated MHSSPT posteriors that hold on held-out data (issue 26, items 3 and 4): whitening that
survives many channels and few samples (reduced-order or diagonal VAR by an information criterion,
shrinkage covariances), a temperature fitted on held-out data (time-blocked), the reliability table
and ECE, and calibrate_densities pointing to calibrate_segments.

The held-out check uses the Tennessee Eastman data (../shared/data/tep): the test is designed on
d00 (nominal) and the fault training sets d01..d21 (the first part of each designs the densities,
the rest fits the temperature) and judged on d00_te and the 21 test sets d01_te..d21_te."""

import gzip
from pathlib import Path

import numpy as np
import pytest

from fdikit import DataError, Signals
from fdikit.detect import (
    VARWhitener,
    WhitenedMHSSPT,
    calibrate_densities,
    design_calibrated_mhsspt,
    design_mhsspt,
    detection_time,
    final_diagnosis,
    reliability,
    shrunk_covariance,
)
from fdikit.detect.mhsspt import decision_outputs

TEP = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "tep"
ONSET = 160


def test_calibrate_densities_one_magnitude_points_to_calibrate_segments():
    rng = np.random.default_rng(0)
    with pytest.raises(DataError, match="need features at >= 2 magnitudes.*calibrate_segments"):
        calibrate_densities(rng.normal(size=(100, 2)), {"f": {1.0: rng.normal(size=(100, 2)) + 1}})


def _diag_ar(T, C, seed, phi=0.8):
    rng = np.random.default_rng(seed)
    mix = np.eye(C) + 0.3 * rng.normal(size=(C, C)) / np.sqrt(C)
    e = rng.normal(size=(T + 200, C)) @ mix.T
    x = np.zeros_like(e)
    for k in range(1, T + 200):
        x[k] = phi * x[k - 1] + e[k]
    return x[200:]


def test_reduced_whitening_where_full_var_refused():
    C = 52
    names = [f"x{i}" for i in range(C)]
    nom = _diag_ar(500, C, 1)
    # the full VAR(10) is refused, naming the samples it needs and the alternatives
    with pytest.raises(DataError, match=r"need >= 5210\); alternatives: .*structure='diagonal'.*reduce=True"
                                        r".*ledoit_wolf"):
        VARWhitener.fit([nom], names)
    # reduced: not even a full VAR(1) fits (530 samples), so one autoregression per channel
    w = VARWhitener.fit([nom], names, reduce=True)
    assert w.info["structure"] == "diagonal" and "reduced" in w.info
    assert w.order == 1 and np.allclose(np.diag(w.coefs[0]), 0.8, atol=0.1)
    assert np.count_nonzero(w.coefs[0] - np.diag(np.diag(w.coefs[0]))) == 0
    # fewer channels: a full VAR of reduced order, by BIC or AIC
    w5 = VARWhitener.fit([nom[:, :5]], names[:5], reduce=True)
    assert w5.info["structure"] == "full" and w5.order == 1 and max(w5.info["bic"]) < 10
    w5a = VARWhitener.fit([nom[:, :5]], names[:5], reduce=True, criterion="aic")
    assert w5a.info["criterion"] == "aic" and w5a.order >= 1
    # design_mhsspt whitens by default where the full VAR is refused, with shrinkage covariances
    seg = _diag_ar(300, C, 2) + np.r_[np.full(10, 3.0), np.zeros(C - 10)]
    t = design_mhsspt(names, [nom], {"f": seg}, p=1e-3)
    assert t.whitener.info["structure"] == "diagonal" and t.whitener.order == 1
    out = t.run(Signals(np.arange(400.0), np.r_[_diag_ar(200, C, 3), _diag_ar(200, C, 4) + seg.mean(0)],
                        names))
    assert final_diagnosis(out)["diagnosis"] == ["P:f"]


def test_shrunk_covariance_keeps_variances_and_is_positive_definite():
    rng = np.random.default_rng(3)
    x = rng.normal(size=(30, 40)) * np.arange(1, 41)  # fewer samples than channels: singular sample cov
    for method in ("ledoit_wolf", "oas"):
        S = shrunk_covariance(x, method)
        np.testing.assert_allclose(np.diag(S), x.var(0, ddof=1), rtol=1e-12)
        assert np.linalg.eigvalsh(S).min() > 0
    with pytest.raises(DataError, match="shrinkage method"):
        shrunk_covariance(x, "ridge")


def test_reliability_table_and_ece():
    P = np.array([[0.95, 0.05], [0.92, 0.08], [0.35, 0.65], [0.45, 0.55], [0.5, 0.5]])
    r = reliability(P, np.array([0, 1, 1, 0, -1]), bins=10)
    assert r["n"] == 4 and r["count"].tolist() == [0, 0, 0, 0, 0, 1, 1, 0, 0, 2]
    assert r["frequency"][9] == 0.5 and r["frequency"][6] == 1.0 and r["frequency"][5] == 0.0
    expect = (2 * abs(0.5 - 0.935) + abs(1 - 0.65) + abs(0 - 0.55)) / 4
    assert abs(r["ece"] - expect) < 1e-12
    assert "ECE" in r["table"]


def test_temperature_batch_streaming_and_round_trip():
    rng = np.random.default_rng(5)
    nom = rng.normal(size=(3000, 2))
    shift = np.array([0.8, 0.0])
    t = design_calibrated_mhsspt(["a", "b"], nom, {"f": rng.normal(size=(1000, 2)) + shift}, p=1e-3)
    assert t.temperature > 0 and len(t.tempering["scores"]) == len(t.tempering["grid"])
    x = np.r_[rng.normal(size=(100, 2)), rng.normal(size=(100, 2)) + shift]
    sig = Signals(np.arange(200.0), x, ["a", "b"])
    batch = t.run(sig).values[0]
    t.reset(1)
    stream = np.array([t.step(x[k]) for k in range(200)]).reshape(batch.shape)
    np.testing.assert_array_equal(batch, stream)
    t2 = WhitenedMHSSPT.from_dict(t.to_dict())
    assert t2.temperature == t.temperature
    np.testing.assert_array_equal(t2.run(sig).values[0], batch)
    with pytest.raises(DataError, match="temperature"):
        WhitenedMHSSPT(t.input_names, dict(zip(t.hypotheses, t.densities)), 1e-3, whitener=t.whitener,
                       temperature=0.0)


def _load(n, te):
    a = np.loadtxt(gzip.open(TEP / f"d{n:02d}{'_te' if te else ''}.dat.gz"))
    return a.T if n == 0 and not te else a


@pytest.fixture(scope="module")
def tep():
    if not (TEP / "d21_te.dat.gz").exists():
        pytest.skip(f"Tennessee Eastman data absent ({TEP})")
    names = [f"x{i}" for i in range(52)]
    train = {f"f{j}": _load(j, False)[20:] for j in range(1, 22)}  # after the training sets' first hour
    test = design_calibrated_mhsspt(names, [_load(0, False)], train, p=1e-3)
    sets = {j: _load(j, True) for j in range(22)}
    runs = {}
    for T in (1.0, test.temperature):
        test.temperature = T
        runs[T] = {j: test.run(Signals(np.arange(960.0), x, names)) for j, x in sets.items()}
    return test, runs


def _judge(runs):
    Ps, ys, early = [], [], 0
    for j, out in runs.items():
        cols, P = decision_outputs(out)
        y = np.zeros(960, int)
        if j:
            y[ONSET:] = cols.index(f"P:f{j}")
            early += bool((P[0, :ONSET, 1:] >= 0.9).any())
        Ps.append(P[0])
        ys.append(y)
    return reliability(np.concatenate(Ps), np.concatenate(ys)), early


def test_tep_posteriors_calibrated_on_held_out_data(tep):
    test, runs = tep
    # where the full VAR(10) of 52 channels is refused (500 nominal samples): a reduced whitening
    assert test.whitener.info["structure"] == "diagonal" and test.whitener.order >= 1
    assert test.temperature > 10
    cal, early = _judge(runs[test.temperature])
    raw, early_raw = _judge(runs[1.0])
    # on the test sets (never seen): of the samples with a posterior >= 0.9, at least 90 % are right
    assert cal["frequency"][-1] >= 0.9 and cal["count"][-1] > 5000
    assert raw["frequency"][-1] < 0.8  # the untempered test is overconfident
    assert cal["ece"] < raw["ece"]
    # no posterior passes 0.9 before the onset on the nominal part of the 21 test sets
    assert early == 0 and early_raw == 21
    out0 = runs[test.temperature][0]
    assert final_diagnosis(out0)["diagnosis"] == ["P:none"]
    assert detection_time(out0)["sample"][0] == -1
    # detectable faults are still found, and right
    for j in (1, 2, 6, 7):
        out = runs[test.temperature][j]
        d = detection_time(Signals(out.t[ONSET:], out.values[:, ONSET:], out.names))
        assert d["fault"] == [f"P:f{j}"] and 0 <= d["sample"][0] < 150
