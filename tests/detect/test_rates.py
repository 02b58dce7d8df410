"""Measured false-alarm rates and their intervals (fdikit.detect.rates; issue 26)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter
from scipy.stats import binom, poisson

from fdikit.detect.rates import measure_alarm_rate, poisson_interval, proportion_interval, verdict
from fdikit.errors import DataError


@pytest.mark.parametrize("k", [0, 1, 7, 40])
def test_poisson_interval_is_the_exact_garwood_interval(k):
    """Independent check: at the upper bound P(X <= k) = 2.5 %, at the lower P(X >= k) = 2.5 %."""
    lo, hi = poisson_interval(k, 2.0)
    assert poisson.cdf(k, hi * 2.0) == pytest.approx(0.025, abs=1e-9)
    if k:
        assert poisson.sf(k - 1, lo * 2.0) == pytest.approx(0.025, abs=1e-9)
    else:
        assert lo == 0.0


@pytest.mark.parametrize("k,n", [(0, 300), (3, 50), (50, 50)])
def test_clopper_pearson_against_the_binomial(k, n):
    lo, hi = proportion_interval(k, n)
    if k < n:
        assert binom.cdf(k, n, hi) == pytest.approx(0.025, abs=1e-9)
    if k > 0:
        assert binom.sf(k - 1, n, lo) == pytest.approx(0.025, abs=1e-9)


def test_onsets_per_hour_count_episodes_once_across_unjudged_samples():
    a = np.zeros(360_000)
    a[100:110] = 1                        # one episode
    a[2000:2003] = 1
    a[2003:2010] = np.nan                 # held samples inside the episode: still one
    a[2010:2015] = 1
    a[9000] = 1                           # a third
    m = measure_alarm_rate([a[:200_000], a[200_000:]], "hour", 0.01)
    assert m["events"] == 3 and m["samples"] == 360_000 - 7
    assert m["rate"] == pytest.approx(3 / ((360_000 - 7) * 0.01 / 3600))
    per_run = measure_alarm_rate([a[:200_000], a[200_000:]], "run", 0.01)
    assert per_run["events"] == 1 and per_run["rate"] == 0.5


def test_per_sample_interval_widens_with_autocorrelation():
    rng = np.random.default_rng(0)
    white = rng.normal(size=200_000) > 2.0
    slow = lfilter([1.0], [1.0, -0.95], rng.normal(size=200_000))
    slow = slow / slow.std() > 2.0
    mw, ms = measure_alarm_rate(white, "sample", 0.01), measure_alarm_rate(slow, "sample", 0.01)
    assert mw["tau"] < 1.5 and ms["tau"] > 5
    width = lambda m: m["interval"][1] - m["interval"][0]    # noqa: E731
    assert width(ms) > 2 * width(mw)
    assert mw["interval"][0] < 0.02275 < mw["interval"][1]   # P(N(0,1) > 2)


def test_verdicts_and_bad_input():
    assert verdict([0.0, 0.1], [0.05, 0.2]) == "inside"
    assert verdict([0.0, 0.1], [0.2, 0.3]) == "above"
    assert verdict([0.2, 0.3], [0.0, 0.1]) == "below"
    with pytest.raises(DataError, match="sample time"):
        measure_alarm_rate(np.zeros(10), "hour", 0.0)
    with pytest.raises(DataError, match="warm-up or held"):
        measure_alarm_rate(np.full(10, np.nan), "hour", 0.01)
    with pytest.raises(DataError, match="per must be"):
        measure_alarm_rate(np.zeros(10), "fortnight", 0.01)
