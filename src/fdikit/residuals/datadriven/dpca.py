"""Dynamic PCA (DPCA): PCA on windows of lagged samples, with the number of lags learnt from data.

Ku, Storer & Georgakis (1995) apply PCA to the windows ``[x_k; x_{k-1}; ...; x_{k-l}]`` so that
the serial correlation of a dynamic process becomes cross-correlation the model can capture;
the T² and Q statistics and their limits are those of static PCA
(:class:`~fdikit.residuals.datadriven.PCAResidual`) on the windows. Russell, Chiang & Braatz
(2000) choose ``l`` by Akaike's criterion for an autoregressive model of the data
(:func:`~fdikit.residuals.datadriven.select_lags`), which is the default here. The streaming
state is the window of the last ``l`` samples.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from .pca import PCAResidual

__all__ = ["DPCAResidual"]


class DPCAResidual(PCAResidual):
    """Dynamic PCA monitor: :class:`~fdikit.residuals.datadriven.PCAResidual` on lagged windows.

    Outputs ``T2`` and ``Q``; the parameters and attributes are those of
    :class:`~fdikit.residuals.datadriven.PCAResidual`. The first ``lags`` outputs of a record
    (``warmup_samples``) see windows padded with the first sample.

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit.residuals.datadriven import PCAResidual
    >>> rng = np.random.default_rng(0)
    >>> x = np.zeros((2000, 2))
    >>> for k in range(1, 2000):                      # x1 follows x0 one sample late
    ...     x[k] = [0.5 * x[k - 1, 0] + rng.standard_normal(), x[k - 1, 0] + 0.1 * rng.standard_normal()]
    >>> dpca = DPCAResidual.fit(x)                    # lags by AIC
    >>> dpca.lags, dpca.n_components, dpca.loadings.shape
    (1, 3, (4, 3))
    >>> y = x[-200:].copy()
    >>> y[100:, 1] = y[100:, 0]                       # the delay is lost
    >>> float((dpca.run_array(y)[0, 100:, 1] > dpca.limits[1]).mean())      # DPCA's Q sees it
    0.79
    >>> pca = PCAResidual.fit(x, n_components=1)
    >>> float((pca.run_array(y)[0, 100:, 1] > pca.limits[1]).mean())        # static PCA does not
    0.0
    """

    @classmethod
    def fit(cls, data: Any, *, channels: Sequence[str] | None = None, n_components: int | str | None = None,
            variance: float = 0.9, lags: int | None = None, max_lags: int = 10,
            level: float = 0.99) -> DPCAResidual:
        """Fit on nominal data; as :meth:`PCAResidual.fit` with ``lags=None`` (AIC) by default."""
        return super().fit(data, channels=channels, n_components=n_components, variance=variance, lags=lags,
                           max_lags=max_lags, level=level)
