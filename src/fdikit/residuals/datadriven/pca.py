"""Principal component analysis (PCA) monitoring: Hotelling's T² and the Q statistic (SPE).

Fitted on nominal data, PCA splits the space of the scaled samples ``v`` (with ``lags > 0``: the
windows of :mod:`~fdikit.residuals.datadriven.lags`) into the ``a`` directions of largest variance
(loadings ``P``, variances ``lam``) and the residual space (Chiang, Russell & Braatz 2001, Ch. 4):

    T²(k) = v_k' P diag(lam)^-1 P' v_k        # eq. (4.12): variation inside the model
    Q(k)  = || (I - P P') v_k ||²             # eq. (4.20): what the model cannot explain

Their control limits come from :mod:`~fdikit.residuals.datadriven.limits` (F distribution for
T², Jackson–Mudholkar for Q) at ``level``; the empirical quantiles over the training data are
stored beside them. :meth:`PCAResidual.contributions` splits both statistics over the channels
for isolation: the Q contribution of a channel is its squared residual, the T² contribution the
complete decomposition ``v_j (P diag(lam)^-1 P' v)_j`` (Alcala & Qin 2009); each sums to the
statistic. Dynamic PCA (:class:`~fdikit.residuals.datadriven.DPCAResidual`) is the same model
on lagged windows.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, ClassVar

import numpy as np

from ...errors import DataError
from .data import check_enough, fit_scaling, training_data
from .lags import LaggedStatistic, lagged, select_lags
from .limits import empirical_limit, q_limit, t2_limit

__all__ = ["PCAResidual", "n_components_parallel"]


def n_components_parallel(eigenvalues: Any, n: int, *, draws: int = 20, seed: int = 0) -> int:
    """Number of components by parallel analysis (Horn 1965; Chiang et al. 2001, Sec. 4.3).

    Keeps the leading eigenvalues of the correlation matrix that exceed the mean eigenvalues of
    the correlation matrices of ``draws`` samples of ``n`` independent Gaussian vectors of the
    same dimension (seeded, so the answer is repeatable).

    Parameters
    ----------
    eigenvalues : array_like (d,)
        Eigenvalues of the correlation matrix of the (autoscaled) training data, decreasing.
    n : int
        Number of training vectors.

    Returns
    -------
    int
        At least 1.

    Examples
    --------
    >>> n_components_parallel([3.0, 1.5, 0.3, 0.2], 500)
    2
    """
    lam = np.asarray(eigenvalues, dtype=float).ravel()
    d = lam.size
    rng = np.random.default_rng(seed)
    ref = np.zeros(d)
    for _ in range(int(draws)):
        g = rng.standard_normal((int(n), d))
        g = (g - g.mean(axis=0)) / g.std(axis=0, ddof=1)
        ref += np.linalg.svd(g, compute_uv=False) ** 2 / (n - 1)
    ref /= draws
    above = lam > ref
    a = d if above.all() else int(np.argmin(above))
    return max(1, min(a, d - 1))


class PCAResidual(LaggedStatistic):
    """PCA monitor: outputs ``T2`` and ``Q`` of each sample (see the module docstring).

    Built by :meth:`fit` from nominal data; the constructor takes the fitted model (what
    :meth:`to_dict` saves). Batch :meth:`run` and streaming ``reset``/``step`` give the same
    numbers; the streaming state is the window of the last ``lags`` samples.

    Parameters
    ----------
    channels : sequence of str
        Channels read (as measurements, ``y_names``).
    mean, scale : array_like (m,)
        Training mean and standard deviation of each channel.
    loadings : array_like ((lags + 1) m, a)
        Orthonormal loadings ``P``.
    eigenvalues : array_like ((lags + 1) m,)
        All eigenvalues of the covariance of the scaled training windows, decreasing; the first
        ``a`` scale T², the others give the Q limit.
    n_train : int
        Number of training windows (for the T² limit).
    lags : int
        Past samples in each window (0: static PCA).
    level : float
        Confidence level of :attr:`limits`.
    empirical_limits : array_like (2,), optional
        Quantiles at ``level`` of T² and Q over the training windows.
    dt : float, optional
        Sample period of the training data (s).

    Attributes
    ----------
    limits : ndarray (2,)
        Control limits of ``T2`` (F distribution) and ``Q`` (Jackson–Mudholkar) at ``level``.
    n_components : int

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit import Signals
    >>> rng = np.random.default_rng(0)
    >>> x = rng.standard_normal((1000, 1)) @ np.ones((1, 3)) + 0.1 * rng.standard_normal((1000, 3))
    >>> pca = PCAResidual.fit(Signals(np.arange(1000.0), x, ["a", "b", "c"]), n_components=1)
    >>> pca.output_names, [round(float(v), 2) for v in pca.limits]
    (['T2', 'Q'], [6.67, 0.1])
    >>> out = pca.run(Signals(np.arange(2.0), [[0.0, 0.0, 0.0], [0.0, 0.0, 3.0]], ["a", "b", "c"]))
    >>> bool(out["Q"][0, 1] > pca.limits[1])      # c broke away from a and b
    True
    >>> pca.reset(1)
    >>> np.allclose(pca.step([], [0.0, 0.0, 3.0]), out.values[:, 1])
    True
    """

    output_units: ClassVar[list[str]] = ["", ""]

    def __init__(self, channels: Sequence[str], mean: Any, scale: Any, loadings: Any, eigenvalues: Any,
                 *, n_train: int, lags: int = 0, level: float = 0.99, empirical_limits: Any = None,
                 dt: float | None = None):
        self._init_window(channels, mean, scale, lags, dt)
        d = (self.lags + 1) * len(self.channels)
        self.loadings = np.asarray(loadings, dtype=float)
        if self.loadings.ndim != 2 or self.loadings.shape[0] != d or not 1 <= self.loadings.shape[1] < d:
            raise DataError(f"loadings must have shape ({d}, a) with 1 <= a < {d}, got {self.loadings.shape}")
        self.eigenvalues = np.asarray(eigenvalues, dtype=float).reshape(d)
        self.n_components = int(self.loadings.shape[1])
        self._lam = self.eigenvalues[:self.n_components]
        if not np.all(self._lam > 0):
            raise DataError(f"the {self.n_components} retained eigenvalues must be > 0, "
                            f"got {self._lam.tolist()}")
        self.n_train = int(n_train)
        self.level = float(level)
        self.limits = self.limit(self.level)
        self.empirical_limits = None if empirical_limits is None else \
            np.asarray(empirical_limits, dtype=float).reshape(2)
        self.output_names = ["T2", "Q"]

    # ------------------------------------------------------------------ design
    @classmethod
    def fit(cls, data: Any, *, channels: Sequence[str] | None = None, n_components: int | str | None = None,
            variance: float = 0.9, lags: int | None = 0, max_lags: int = 10,
            level: float = 0.99) -> PCAResidual:
        """Fit the model on nominal data.

        Parameters
        ----------
        data : Signals or array_like (T, m) or (runs, T, m)
            Nominal training data (every run gives its own windows).
        channels : sequence of str, optional
            Channels to monitor (default: all; for an array, the names of its columns).
        n_components : int or "parallel", optional
            Number of components ``a``; ``"parallel"``: by parallel analysis
            (:func:`n_components_parallel`); default: the fewest that explain ``variance``.
        variance : float
            Fraction of the total variance the components explain when ``n_components`` is None.
        lags : int or None
            Past samples in each window (0: static PCA); None: :func:`select_lags` (AIC).
        max_lags : int
            Largest number of lags tried when ``lags`` is None.
        level : float
            Confidence level of the control limits.

        Returns
        -------
        PCAResidual

        Raises
        ------
        DataError
            A non-finite or constant channel (named), too few samples for the window dimension,
            or a number of components that leaves no residual space.
        """
        values, names, dt = training_data(data, channels)
        mean, scale = fit_scaling(values, names)
        z = (values - mean) / scale
        if lags is None:
            lags = select_lags(z, max_lags)
        lags = int(lags)
        if lags < 0:
            raise DataError(f"lags must be >= 0, got {lags}")
        d = (lags + 1) * len(names)
        rows = [lagged(zr, lags) for zr in z if zr.shape[0] > lags]
        n = sum(r.shape[0] for r in rows)
        check_enough(n, d, cls.__name__, runs=z.shape[0], samples=z.shape[1], lags=f"{lags}-lag")
        V = np.concatenate(rows)
        _, s, wt = np.linalg.svd(V, full_matrices=False)
        eig = s ** 2 / (n - 1)
        # deterministic signs: the largest entry of each loading is positive
        flip = np.sign(wt[np.arange(d), np.argmax(np.abs(wt), axis=1)])
        wt *= flip[:, None]
        if n_components is None:
            if not 0.0 < float(variance) <= 1.0:
                raise DataError(f"variance must lie in (0, 1], got {variance}")
            frac = np.cumsum(eig) / np.sum(eig)
            a = min(int(np.searchsorted(frac, float(variance) - 1e-12)) + 1, d - 1)
        elif isinstance(n_components, str):
            if n_components != "parallel":
                raise DataError(f"n_components must be an int, 'parallel' or None, got {n_components!r}")
            a = n_components_parallel(eig, n)
        else:
            a = int(n_components)
            if not 1 <= a < d:
                raise DataError(f"n_components must lie in 1..{d - 1} (the window has dimension {d}; "
                                f"{d} components leave no residual space), got {n_components}")
        gen = cls(names, mean, scale, wt[:a].T, eig, n_train=n, lags=lags, level=level, dt=dt)
        st = gen._statistics(V)
        gen.empirical_limits = np.array([empirical_limit(st[:, i], level) for i in range(2)])
        return gen

    def limit(self, level: float | None = None) -> np.ndarray:
        """Theoretical control limits ``[T2, Q]`` at ``level`` (default: the model's)."""
        level = self.level if level is None else float(level)
        return np.array([t2_limit(self.n_components, self.n_train, level),
                         q_limit(self.eigenvalues[self.n_components:], level)])

    @property
    def explained_variance_ratio(self) -> float:
        """Fraction of the training variance the retained components explain."""
        return float(np.sum(self._lam) / np.sum(self.eigenvalues))

    # ------------------------------------------------------------------ runtime
    def _statistics(self, V: np.ndarray) -> np.ndarray:
        t = V @ self.loadings
        t2 = np.sum(t * t / self._lam, axis=1)       # Chiang et al. 2001, eq. (4.12)
        e = V - t @ self.loadings.T
        q = np.sum(e * e, axis=1)                    # eq. (4.20)
        return np.stack([t2, q], axis=1)

    def contributions(self, data: Any) -> dict[str, np.ndarray]:
        """Contribution of each channel to ``T2`` and ``Q`` at every sample (for isolation).

        Parameters
        ----------
        data : Signals or array_like (T, m) or (runs, T, m)
            A record of the model's channels (windows built as in :meth:`run`).

        Returns
        -------
        dict
            ``"T2"`` and ``"Q"``: arrays ``(runs, T, m)`` in the order of :attr:`channels`, each
            summing over the channels to the statistic (lags summed per channel). The Q part is
            the squared residual (>= 0); the T² part ``v_j (P diag(lam)^-1 P' v)_j`` can be
            negative.

        Examples
        --------
        >>> import numpy as np
        >>> rng = np.random.default_rng(1)
        >>> x = rng.standard_normal((500, 1)) @ np.ones((1, 3)) + 0.1 * rng.standard_normal((500, 3))
        >>> pca = PCAResidual.fit(x, channels=["a", "b", "c"], n_components=1)
        >>> c = pca.contributions(np.array([[0.0, 0.0, 3.0]]))
        >>> int(np.argmax(c["Q"][0, 0]))                    # channel c
        2
        >>> bool(np.isclose(c["Q"].sum(), pca.run_array(np.array([[0.0, 0.0, 3.0]]))[0, 0, 1]))
        True
        """
        V = self.windows(data)
        runs, T = V.shape[:2]
        m = len(self.channels)
        t = V @ self.loadings
        g = (t / self._lam) @ self.loadings.T
        e = V - t @ self.loadings.T
        shape = (runs, T, self.lags + 1, m)
        return {"T2": (V * g).reshape(shape).sum(axis=2), "Q": (e * e).reshape(shape).sum(axis=2)}

    # ------------------------------------------------------------------ artifacts
    def to_dict(self) -> dict[str, Any]:
        """The fitted model as plain data (arrays stay arrays; see :mod:`fdikit.base.artifacts`)."""
        return {"channels": list(self.channels), "mean": self.mean.copy(), "scale": self.scale.copy(),
                "loadings": self.loadings.copy(), "eigenvalues": self.eigenvalues.copy(),
                "n_train": self.n_train, "lags": self.lags, "level": self.level,
                "empirical_limits": None if self.empirical_limits is None else self.empirical_limits.copy(),
                "dt": self.train_dt}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> PCAResidual:
        """Rebuild from :meth:`to_dict`."""
        return cls(d["channels"], d["mean"], d["scale"], d["loadings"], d["eigenvalues"],
                   n_train=int(d["n_train"]), lags=int(d["lags"]), level=float(d["level"]),
                   empirical_limits=d.get("empirical_limits"), dt=d.get("dt"))
