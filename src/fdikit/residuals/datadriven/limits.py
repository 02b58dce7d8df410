"""Control limits of the data-driven monitoring statistics: T² (F distribution), Q (Jackson–
Mudholkar) and empirical quantiles.

* :func:`t2_limit`: Hotelling's T² of ``a`` scores of a *new* sample, with the covariance
  estimated from ``n`` training samples, is ``a (n-1)(n+1) / (n (n-a))`` times an
  ``F(a, n-a)`` variable (Tracy, Young & Mason 1992; Chiang, Russell & Braatz 2001, eq. (4.13)).
* :func:`q_limit`: the squared prediction error of a Gaussian vector is a weighted sum of
  chi-squared variables, the weights being the eigenvalues ``lam`` left out of the model; the
  Jackson & Mudholkar (1979) normal approximation gives its quantile (Chiang et al. 2001,
  eq. (4.22)). When the eigenvalues are so skewed that its exponent ``h0`` is not positive, the
  Box (1954) approximation ``g chi2(h)`` with matching mean and variance is used instead.
* :func:`empirical_limit`: the quantile of the statistic over the training data themselves,
  stored beside the theoretical limits to show how far the data are from the assumptions
  (independent Gaussian samples).
"""

from __future__ import annotations

import numpy as np
from scipy import stats

from ...errors import DataError

__all__ = ["empirical_limit", "q_limit", "t2_limit"]


def _check_level(level: float) -> float:
    level = float(level)
    if not 0.0 < level < 1.0:
        raise DataError(f"confidence level must lie in (0, 1), got {level}")
    return level


def t2_limit(a: int, n: int, level: float = 0.99) -> float:
    """Upper control limit of Hotelling's T² of ``a`` scores from ``n`` training samples.

    Parameters
    ----------
    a : int
        Number of retained scores (components, states), ``1 <= a < n``.
    n : int
        Number of training samples the covariance was estimated from.
    level : float
        Confidence level in (0, 1); the limit is exceeded by ``1 - level`` of nominal samples.

    Returns
    -------
    float

    Examples
    --------
    >>> round(t2_limit(2, 100, 0.99), 4)
    9.8531
    """
    level = _check_level(level)
    a, n = int(a), int(n)
    if not 1 <= a < n:
        raise DataError(f"a T² limit needs 1 <= a < n (scores {a}, training samples {n})")
    # Chiang et al. 2001, eq. (4.13)
    return float(a * (n - 1) * (n + 1) / (n * (n - a)) * stats.f.ppf(level, a, n - a))


def q_limit(lam, level: float = 0.99) -> float:
    """Upper control limit of the squared prediction error ``Q`` (SPE) by Jackson–Mudholkar.

    Parameters
    ----------
    lam : array_like
        Eigenvalues of the covariance of the residual space (those left out of the model), >= 0.
    level : float
        Confidence level in (0, 1).

    Returns
    -------
    float
        ``0.0`` when every eigenvalue is zero (no residual variance).

    Examples
    --------
    >>> round(q_limit([1.0, 1.0, 1.0], 0.99), 3)    # the exact chi2(3) quantile is 11.345
    11.369
    """
    level = _check_level(level)
    lam = np.asarray(lam, dtype=float).ravel()
    if lam.size == 0:
        raise DataError("a Q limit needs at least one residual eigenvalue (the model leaves no residual "
                        "space)")
    if not np.all(np.isfinite(lam)) or (lam < 0).any():
        raise DataError(f"residual eigenvalues must be finite and >= 0, got {lam.tolist()}")
    th1, th2, th3 = (float(np.sum(lam ** i)) for i in (1, 2, 3))
    if th1 == 0.0:
        return 0.0
    h0 = 1.0 - 2.0 * th1 * th3 / (3.0 * th2 ** 2)
    if h0 <= 0.0:  # Box (1954): g chi2(h) with the same mean and variance
        g, h = th2 / th1, th1 ** 2 / th2
        return float(g * stats.chi2.ppf(level, h))
    c = stats.norm.ppf(level)
    # Jackson & Mudholkar 1979; Chiang et al. 2001, eq. (4.22)
    return float(th1 * (c * np.sqrt(2.0 * th2 * h0 ** 2) / th1 + 1.0 + th2 * h0 * (h0 - 1.0) / th1 ** 2)
                 ** (1.0 / h0))


def empirical_limit(values, level: float = 0.99) -> float:
    """The ``level`` quantile of a statistic over (training) samples.

    Examples
    --------
    >>> import numpy as np
    >>> empirical_limit(np.arange(101.0), 0.99)
    99.0
    """
    level = _check_level(level)
    v = np.asarray(values, dtype=float).ravel()
    if v.size == 0 or not np.all(np.isfinite(v)):
        raise DataError("an empirical limit needs finite values of the statistic")
    return float(np.quantile(v, level))
