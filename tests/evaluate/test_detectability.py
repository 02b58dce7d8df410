"""Neyman-Pearson (known-signal) detectability bound, generic and for the ABS faults."""

import io
import json
from contextlib import redirect_stdout

import numpy as np
import pytest

from fdikit import DataError
from fdikit.systems.abs.detectability import abs_detectability, known_signal_dprime


def test_known_signal_dprime_matches_the_exact_mahalanobis_norm():
    rng = np.random.default_rng(0)
    A = rng.normal(size=(6, 6))
    Sigma = A @ A.T + 0.5 * np.eye(6)
    X = rng.multivariate_normal(np.zeros(6), Sigma, size=200_000)
    delta = rng.normal(size=6)
    exact = float(np.sqrt(delta @ np.linalg.solve(Sigma, delta)))
    assert known_signal_dprime(delta, X, shrinkage=0.0) == pytest.approx(exact, rel=0.01)


def test_known_signal_dprime_is_the_np_detection_rate():
    """The likelihood-ratio test for the known shift reaches Phi(d' - z_alpha) on fresh samples."""
    from scipy.stats import norm

    rng = np.random.default_rng(1)
    Sigma = np.array([[1.0, 0.8], [0.8, 1.0]])
    delta = np.array([1.0, -1.0])  # along the weak direction: d' = sqrt(2 / 0.2) = 3.16
    X0 = rng.multivariate_normal(np.zeros(2), Sigma, size=100_000)
    dp = known_signal_dprime(delta, X0, shrinkage=0.0)
    assert dp == pytest.approx(np.sqrt(10.0), rel=0.02)
    w = np.linalg.solve(Sigma, delta) / dp  # LR statistic, unit variance under H0
    alpha = 0.01
    q = norm.isf(alpha)
    X1 = rng.multivariate_normal(delta, Sigma, size=100_000)
    assert np.mean(X0 @ w > q) == pytest.approx(alpha, abs=0.002)
    assert np.mean(X1 @ w > q) == pytest.approx(norm.sf(q - dp), abs=0.01)


def test_bad_input():
    with pytest.raises(DataError, match="more nominal samples"):
        known_signal_dprime(np.ones(3), np.ones((3, 3)))
    with pytest.raises(DataError, match=r"must be \(n, 2\)"):
        known_signal_dprime(np.ones(2), np.ones((10, 3)))
    with pytest.raises(DataError, match="singular"):
        known_signal_dprime(np.ones(2), np.hstack([np.random.default_rng(0).normal(size=(50, 1)),
                                                   np.zeros((50, 1))]), shrinkage=0.0)
    with pytest.raises(DataError, match="fault must be"):
        abs_detectability("F0", 0.0)
    with pytest.raises(DataError, match="window"):
        abs_detectability("F3", 0.02, window=(2.0, 1.0))
    with pytest.raises(DataError, match="runs"):
        abs_detectability("F3", 0.02, runs=10)


@pytest.fixture(scope="module")
def bounds():
    kw = dict(runs=1500, block=10)
    return {f: abs_detectability(f, m, **kw) for f, m in (("F5", 0.15), ("F4", 0.02), ("F3", 0.02))}


def test_tau_m_fault_is_undetectable_and_k_f_is_not(bounds):
    """23 dB: the +15 % tau_m fault leaves d' < 1.5 for the whole record (its parameter stops acting once
    P_m settles); +2 % K_f, d' > 8; +2 % I_w before the ABS engages, d' < 2 (it acts later, so the
    bound is for the window only). Without the process noise, every one of them would be visible."""
    f5, f4, f3 = bounds["F5"], bounds["F4"], bounds["F3"]
    assert f5["parameter_acts_after_window"] is False
    assert f5["d_prime_whole_record_bound"] < 1.5 and f5["pd_bound_whole_record"] < 0.02
    assert f5["d_prime_measurement_only"] > 6
    assert f4["parameter_acts_after_window"] is True and f4["d_prime_whole_record_bound"] is None
    assert f4["d_prime"] < 2.0 < f4["d_prime_measurement_only"]
    assert f3["d_prime"] > 8 and f3["pd_bound"] > 0.999
    # the tau_m state left at the window's end is well inside the nominal spread (T_b, dT_b)
    for i in (2, 3):
        assert abs(f5["state_delta_end"][i]) < 0.5 * f5["state_std_end"][i]


def test_cli_detectability_json():
    import argparse

    from fdikit.commands.abs_detectability import add_detectability_parser

    top = argparse.ArgumentParser()
    add_detectability_parser(top.add_subparsers())
    args = top.parse_args(["detectability", "--fault", "F5", "--magnitude", "0.15", "--runs", "300",
                           "--block", "20", "--json"])
    buf = io.StringIO()
    with redirect_stdout(buf):
        assert args.func(args) == 0
    lines = buf.getvalue().strip().splitlines()
    assert len(lines) == 1
    d = json.loads(lines[0])
    assert d["fault"] == "F5" and 0.0 <= d["pd_bound"] <= 1.0 and d["quantities"] == 20
