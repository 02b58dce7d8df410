"""Control limits calibrated on held-out nominal records (fdikit.detect.calibrated_limits): the rate
they claim holds on fresh nominal data, where the theoretical limits do not; TEP (skipped without
the data): fitted on d00, calibrated on a later block, measured on d00_te."""

from pathlib import Path

import numpy as np
import pytest
from scipy.signal import lfilter

from fdikit import DataError
from fdikit.detect import (
    CalibratedLimits,
    calibrate_limits,
    fit_calibrated,
    held_out_limit,
    predictive_interval,
)
from fdikit.residuals import CVAResidual, DPCAResidual, PCAResidual

TEP = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "tep"


def _ar_data(seed, T, m=4, phi=0.9):
    """Strongly autocorrelated channels with one common factor: the F / Jackson-Mudholkar limits
    (independent samples) are wrong for them."""
    rng = np.random.default_rng(seed)
    common = lfilter([1.0], [1.0, -phi], rng.standard_normal(T))
    own = lfilter([1.0], [1.0, -phi], rng.standard_normal((T, m)), axis=0)
    return common[:, None] @ np.ones((1, m)) + 0.5 * own


def test_the_stated_interval_covers_the_rate_on_fresh_records():
    """30 independent designs on AR(0.9) data: the rate measured on a fresh record lies inside the
    predictive interval in >= 85 % of them (95 % intervals), for T2 and Q alike."""
    inside, n = 0, 0
    for seed in range(30):
        x = _ar_data(seed, 9000)
        pca = PCAResidual.fit(x[:3000], n_components=1)
        cal = calibrate_limits(pca, x[3000:6000], 0.95)
        rate = (pca.run_array(x[6000:])[0] > cal.limits).mean(axis=0)
        iv = cal.predictive(3000)
        inside += int(np.sum((iv[:, 0] <= rate) & (rate <= iv[:, 1])))
        n += 2
    assert inside / n >= 0.85, inside / n


def test_effective_samples_count_the_autocorrelation():
    x = _ar_data(1, 6000)
    pca = PCAResidual.fit(x[:3000], n_components=1)
    cal = calibrate_limits(pca, x[3000:], 0.95)
    assert np.all(cal.effective_samples < 0.5 * cal.samples)      # tau of AR(0.9) windows >> 1
    white = calibrate_limits(pca, np.random.default_rng(0).standard_normal((3000, 4)), 0.95)
    assert np.all(white.effective_samples > 0.7 * white.samples)
    # fewer effective samples: a wider interval
    assert np.all(np.diff(cal.interval, axis=1) > np.diff(white.interval, axis=1))


def test_held_out_limit_is_the_conformal_order_statistic():
    v = np.arange(1.0, 100.0)                        # 99 samples: rank ceil(100 * 0.9) = 90
    d = held_out_limit(v, 0.9)
    assert d["limit"] == 90.0 and d["samples"] == 99
    d = held_out_limit([v[:50], v[50:]], 0.99)      # records pooled
    assert d["limit"] == 99.0
    # few effective samples for the target: said so, and the interval reaches far above it
    small = held_out_limit(np.random.default_rng(0).standard_normal(40), 0.99)
    assert not small["supported"] and small["interval"][1] > 0.05


def test_predictive_is_wider_than_the_claim():
    lo, hi = predictive_interval(0.99, 300.0, 3.0, 960)
    cal_lo, cal_hi = held_out_limit(np.random.default_rng(0).standard_normal(900), 0.99)["interval"]
    assert lo <= cal_lo and hi >= cal_hi


def test_fit_calibrated_splits_in_time_and_round_trips():
    x = _ar_data(2, 4000)
    gen, cal = fit_calibrated(DPCAResidual, x, lags=1, n_components=2, fraction=0.25)
    assert gen.n_train == 3000 - 1 and cal.samples == 1000 - 1      # the held-out warm-up left out
    back = CalibratedLimits.from_dict(cal.to_dict())
    np.testing.assert_array_equal(back.limits, cal.limits)
    np.testing.assert_array_equal(back.interval, cal.interval)
    assert back.names == ["T2", "Q"] and back.theoretical is not None


def test_bad_input_is_named():
    pca = PCAResidual.fit(np.random.default_rng(0).standard_normal((500, 3)), n_components=1)
    with pytest.raises(DataError, match="level"):
        calibrate_limits(pca, np.zeros((100, 3)), 1.5)
    with pytest.raises(DataError, match="record 1, sample 7"):
        held_out_limit([np.ones(10), np.r_[np.ones(7), np.nan, 1.0]], 0.9)
    with pytest.raises(DataError, match="ONE record"):
        fit_calibrated(PCAResidual, np.zeros((2, 100, 3)))
    with pytest.raises(DataError, match="columns"):
        lim = CalibratedLimits(["T2", "Q"], np.ones(2), 0.99, np.zeros((2, 2)), 10, np.ones(2))
        lim.exceed(np.ones((4, 3)))


@pytest.mark.slow
def test_tep_calibrated_limits_against_the_theoretical_ones():
    """TEP: fitted on d00[:340], limits at 99 % on d00[340:] plus the pre-onset parts of the
    fault test sets (other nominal runs); on d00_te (never seen) each calibrated limit's rate lies
    within its predictive interval, and the worst one is far below the worst theoretical one."""
    if not (TEP / "d21_te.dat.gz").exists():
        pytest.skip(f"Tennessee Eastman data absent ({TEP})")
    import gzip

    def rd(name):
        return np.loadtxt(gzip.open(TEP / f"{name}.dat.gz"))
    d00, d00te = rd("d00").T, rd("d00_te")
    pre = [rd(f"d{k:02d}_te")[:160] for k in range(1, 22)]
    worst_cal, worst_theo = 0.0, 0.0
    for gen in (PCAResidual.fit(d00[:340], n_components="parallel"),
                DPCAResidual.fit(d00[:340], n_components="parallel", lags=2),
                CVAResidual.fit(d00[:340], lags=2)):
        cal = calibrate_limits(gen, [d00[340:], *pre], 0.99)
        S = gen.run_array(d00te)[0]
        rate, theo = (S > cal.limits).mean(axis=0), (S > cal.theoretical).mean(axis=0)
        iv = cal.predictive(S.shape[0])
        assert np.all((iv[:, 0] <= rate) & (rate <= iv[:, 1])), (type(gen).__name__, rate, iv)
        worst_cal, worst_theo = max(worst_cal, rate.max()), max(worst_theo, theo.max())
    assert worst_cal <= 0.03 and worst_theo > 0.05, (worst_cal, worst_theo)


def test_min_tau_floors_the_autocorrelation_time():
    """A statistic known to be correlated (an EWMA) is not credited with more effective samples than
    ``samples / min_tau``; the limit itself is unchanged and the default changes nothing."""
    v = np.random.default_rng(3).standard_normal(2000)
    base = held_out_limit(v, 0.95)
    assert held_out_limit(v, 0.95, min_tau=1.0) == base
    d = held_out_limit(v, 0.95, min_tau=20.0)
    assert d["limit"] == base["limit"] and d["tau"] == 20.0 and d["effective_samples"] == 100.0
    assert d["interval"][1] - d["interval"][0] > base["interval"][1] - base["interval"][0]
