"""How detectable is a fault at all? The Neyman-Pearson bound of a known fault signature.

Whatever residual generator and test are used, no detector of a fault whose effect on the
measurements is a *known* deterministic change ``delta`` (known size, sign and onset) in
Gaussian noise of covariance ``Sigma`` can beat the likelihood-ratio test for that change:
with ``d' = sqrt(delta' Sigma^-1 delta)``, its detection probability at false-alarm
probability ``alpha`` is ``Phi(d' - z_alpha)`` (``z_alpha`` the upper ``alpha`` quantile of the
standard normal). A real detector knows less (the size, sign and exact trajectory), so this is
an upper bound.

:func:`known_signal_dprime` computes ``d'`` from nominal Monte Carlo samples (covariance
estimated with shrinkage toward its diagonal). :func:`fdikit.systems.abs.detectability.abs_detectability`
applies it to the ABS plant (luo-et-al).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import DataError

__all__ = ["known_signal_dprime"]


def known_signal_dprime(delta: Any, nominal: Any, *, shrinkage: float = 0.05) -> float:
    """``d' = sqrt(delta' Sigma^-1 delta)`` with ``Sigma`` estimated from nominal samples.

    Parameters
    ----------
    delta : array_like (p,)
        The fault's known effect on the p observed quantities.
    nominal : array_like (n, p)
        Nominal samples of those quantities (n > p).
    shrinkage : float in [0, 1)
        ``Sigma = (1 - shrinkage) S + shrinkage diag(S)`` (S the sample covariance): a little
        shrinkage keeps the inverse of a sample covariance from inflating ``d'``.

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> x = rng.normal(size=(20000, 2)) * [1.0, 2.0]
    >>> round(known_signal_dprime([3.0, 4.0], x, shrinkage=0.0), 1)   # sqrt(9/1 + 16/4)
    3.6
    """
    d = np.asarray(delta, float).ravel()
    X = np.asarray(nominal, float)
    if X.ndim != 2 or X.shape[1] != d.size:
        raise DataError(f"nominal samples must be (n, {d.size}), got {X.shape}")
    if X.shape[0] <= X.shape[1]:
        raise DataError(f"need more nominal samples ({X.shape[0]}) than quantities ({X.shape[1]})")
    if not 0.0 <= shrinkage < 1.0:
        raise DataError(f"shrinkage must be in [0, 1), got {shrinkage}")
    if not (np.all(np.isfinite(d)) and np.all(np.isfinite(X))):
        raise DataError("delta and the nominal samples must be finite")
    S = np.cov(X, rowvar=False).reshape(d.size, d.size)
    S = (1.0 - shrinkage) * S + shrinkage * np.diag(np.diag(S))
    try:
        c = np.linalg.cholesky(S)
    except np.linalg.LinAlgError:
        raise DataError("the nominal covariance is singular (a quantity without noise?)") from None
    z = np.linalg.solve(c, d)
    return float(np.sqrt(z @ z))
