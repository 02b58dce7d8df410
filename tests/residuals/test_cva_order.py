"""The CVA order by held-out prediction (fdikit.residuals.datadriven.cva.heldout_order), the new
default of CVAResidual.fit: it finds the order of a simulated state-space system, and on the
Tennessee Eastman nominal set it keeps far fewer states than the former variance rule (55)."""

from pathlib import Path

import numpy as np
import pytest

from fdikit import DataError
from fdikit.residuals import CVAResidual
from fdikit.residuals.datadriven import heldout_order

TEP = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "tep"


def _two_state(seed, T=4000):
    rng = np.random.default_rng(seed)
    A = np.array([[0.9, 0.2], [-0.2, 0.9]])
    C = rng.standard_normal((5, 2))
    x, Y = np.zeros(2), np.zeros((T, 5))
    for k in range(T):
        x = A @ x + rng.standard_normal(2)
        Y[k] = C @ x + 0.5 * rng.standard_normal(5)
    return Y


@pytest.mark.parametrize("seed", range(4))
def test_heldout_order_finds_two_states(seed):
    Y = _two_state(seed)
    z = (Y - Y.mean(0)) / Y.std(0)
    assert heldout_order(z[None], 3, 3) == 2
    assert CVAResidual.fit(Y, lags=3).order == 2                 # the default
    assert CVAResidual.fit(Y, lags=3, order="variance").order >= 1   # the former rule still there


def test_bad_order_arguments():
    Y = _two_state(0, 600)
    with pytest.raises(DataError, match="order must be"):
        CVAResidual.fit(Y, lags=2, order="aic")
    with pytest.raises(DataError, match="holdout"):
        CVAResidual.fit(Y, lags=2, holdout=1.0)
    with pytest.raises(DataError, match="heldout"):
        heldout_order(((Y - Y.mean(0)) / Y.std(0))[None, :20], 3, 3)


def test_tep_order_is_far_below_the_variance_rule():
    if not (TEP / "d00.dat.gz").exists():
        pytest.skip(f"Tennessee Eastman data absent ({TEP})")
    import gzip

    d00 = np.loadtxt(gzip.open(TEP / "d00.dat.gz")).T
    new, old = CVAResidual.fit(d00, lags=2), CVAResidual.fit(d00, lags=2, order="variance")
    assert old.order == 55
    assert 5 <= new.order <= 30, new.order
