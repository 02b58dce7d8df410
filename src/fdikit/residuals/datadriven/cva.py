"""Canonical variate analysis (CVA) monitoring: T² of the states, T² of the residual variates, Q.

Russell, Chiang & Braatz (2000) (and Chiang et al. 2001, Ch. 7): with the scaled samples ``z``,
the past vector ``p_k = [z_k; z_{k-1}; ...; z_{k-p+1}]`` and the future vector
``f_k = [z_{k+1}; ...; z_{k+f}]`` of the training data give the covariances ``S_pp``, ``S_ff``,
``S_fp``; with Cholesky factors ``S_pp = L_p L_p'`` and ``S_ff = L_f L_f'``, the SVD

    L_f^-1 S_fp L_p^-T = U diag(sigma) V'

gives the canonical correlations ``sigma`` and ``J = V' L_p^-1``, whose rows are uncorrelated
with unit variance on the training data. The first ``n`` rows (``J_n``) give the states
``x_k = J_n p_k``, the others the residual variates; per sample:

    T2s(k) = || J_n p_k ||²                 # the states
    T2r(k) = || J_r p_k ||²                 # the residual variates
    Q(k)   = || p_k - S_pp J_n' J_n p_k ||² # the past the states do not reconstruct

(The past here includes the current sample, so the statistics at ``k`` react to ``z_k``; this is
the paper's past vector shifted by one sample.) Limits: T2s and T2r from the F distribution
with ``n`` and ``p m - n`` degrees of freedom (Russell et al. 2000), Q by Jackson–Mudholkar from
the eigenvalues of the covariance of the training residuals. The streaming state is the window
of the last ``p - 1`` samples.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, ClassVar

import numpy as np
import scipy.linalg as sla

from ...errors import DataError
from .data import check_enough, fit_scaling, training_data
from .lags import LaggedStatistic, lagged, select_lags
from .limits import empirical_limit, q_limit, t2_limit

__all__ = ["CVAResidual", "heldout_order"]


def _chol(S: np.ndarray, what: str) -> np.ndarray:
    try:
        return np.linalg.cholesky(S)
    except np.linalg.LinAlgError:
        ev = np.linalg.eigvalsh(S)
        raise DataError(f"CVA: the covariance of the {what} vectors is singular (smallest eigenvalue "
                        f"{ev[0]:.3g}, largest {ev[-1]:.3g}): some channels are (lagged) linear combinations "
                        "of others; drop them or use fewer lags") from None


def _canonical(W: np.ndarray, f: int, m: int) -> tuple:
    """``(Spp, Sfp, sigma, J)`` of windows ``W`` (newest first: future | past)."""
    n = W.shape[0]
    F, P = W[:, :f * m], W[:, f * m:]
    Spp = P.T @ P / (n - 1)
    Sff = F.T @ F / (n - 1)
    Sfp = F.T @ P / (n - 1)
    Lp, Lf = _chol(Spp, "past"), _chol(Sff, "future")
    H = sla.solve_triangular(Lf, Sfp, lower=True)
    H = sla.solve_triangular(Lp, H.T, lower=True).T        # L_f^-1 S_fp L_p^-T
    _, sigma, Vt = np.linalg.svd(H, full_matrices=True)
    J = sla.solve_triangular(Lp, Vt.T, lower=True, trans="T").T   # V' L_p^-1
    return Spp, Sfp, sigma, J


def heldout_order(z: np.ndarray, past: int, future: int, holdout: float = 0.3) -> int:
    """Number of CVA states that best predicts held-out future vectors.

    The canonical variates are fitted on the first ``1 - holdout`` of every run of ``z``; the
    future vector of each held-out window is predicted from the first ``n`` states,
    ``f_hat = S_fp J_n' J_n p`` (the least-squares prediction, since ``J S_pp J' = I``), and the
    fewest states whose mean squared error over the held-out windows is within one standard error
    of the smallest is returned (the standard error of the paired difference of its per-window
    errors and those of the best order). More states fit the training future better
    but, beyond the dynamics that the data can identify, predict held-out data worse.

    Parameters
    ----------
    z : ndarray (runs, T, m)
        Scaled nominal data.
    past, future : int
        Samples in the past (the current one included) and the future vectors.
    holdout : float
        Held-out fraction of each run, in (0, 1).

    Returns
    -------
    int
        In ``1 .. past m - 1``.

    Raises
    ------
    DataError
        A bad ``holdout``, or too few samples in the fit part or in the held-out block.

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> x = np.zeros((3000, 3))
    >>> for k in range(1, 3000):            # one slow state seen by all channels, plus white noise
    ...     x[k, 0] = 0.95 * x[k - 1, 0] + rng.standard_normal()
    >>> y = x[:, :1] @ np.ones((1, 3)) + rng.standard_normal((3000, 3))
    >>> heldout_order(((y - y.mean(0)) / y.std(0))[None], 2, 2)
    1
    """
    if not 0.0 < float(holdout) < 1.0:
        raise DataError(f"holdout must lie in (0, 1), got {holdout}")
    m = z.shape[2]
    q = past * m
    fit, test = [], []
    for zr in z:
        cut = round((1.0 - float(holdout)) * zr.shape[0])
        if cut >= past + future:
            fit.append(lagged(zr[:cut], past + future - 1))
        if zr.shape[0] - cut >= past + future:
            test.append(lagged(zr[cut:], past + future - 1))
    n_fit = sum(w.shape[0] for w in fit)
    if n_fit <= max(past, future) * m or not test:
        raise DataError(f"order='heldout' needs more than {max(past, future) * m} windows in the fit part "
                        f"and some in the held-out {holdout:.2f} of the runs, got {n_fit} and "
                        f"{sum(w.shape[0] for w in test)}; give the order or more nominal data")
    _, Sfp, _, J = _canonical(np.concatenate(fit), future, m)
    Wt = np.concatenate(test)
    Ft, Pt = Wt[:, :future * m], Wt[:, future * m:]
    X = Pt @ J.T                        # every held-out state
    C = Sfp @ J.T                       # the future's coefficient on each state
    resid = Ft.copy()
    err = np.empty((q - 1, Ft.shape[0]))
    for i in range(q - 1):
        resid -= np.outer(X[:, i], C[:, i])
        err[i] = np.mean(resid * resid, axis=1)
    mse = err.mean(axis=1)
    best = int(np.argmin(mse))
    # one-standard-error rule: the fewest states whose held-out error is within one standard error
    # of the best (the error curve is flat near its minimum; its noise should not add states)
    diff = err - err[best]
    se = diff.std(axis=1, ddof=1) / np.sqrt(Ft.shape[0])
    return int(np.flatnonzero(diff.mean(axis=1) <= se)[0]) + 1


class CVAResidual(LaggedStatistic):
    """CVA monitor: outputs ``T2s``, ``T2r`` and ``Q`` of each sample (see the module docstring).

    Built by :meth:`fit` from nominal data; the constructor takes the fitted model (what
    :meth:`to_dict` saves). Batch :meth:`run` and streaming ``reset``/``step`` give the same
    numbers.

    Parameters
    ----------
    channels : sequence of str
        Channels read (as measurements, ``y_names``).
    mean, scale : array_like (m,)
        Training mean and standard deviation of each channel.
    J : array_like (p m, p m)
        The canonical variates of the past, ``V' L_p^-1``.
    order : int
        Number of states ``n`` (``1 <= n < p m``).
    residual_map : array_like (p m, p m)
        ``I - S_pp J_n' J_n``: the residual of the past vector.
    residual_eigenvalues : array_like (p m,)
        Eigenvalues of the training covariance of that residual (for the Q limit).
    correlations : array_like
        Canonical correlations ``sigma``, decreasing.
    n_train : int
        Number of training (past, future) pairs.
    past, future : int
        Samples in the past vector (``p``, the current one included) and in the future vector.
    level : float
        Confidence level of :attr:`limits`.
    empirical_limits : array_like (3,), optional
        Quantiles at ``level`` of the three statistics over the training data.
    dt : float, optional
        Sample period of the training data (s).

    Attributes
    ----------
    limits : ndarray (3,)
        Control limits of ``T2s``, ``T2r`` (F distribution) and ``Q`` (Jackson–Mudholkar).

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> x = np.zeros((3000, 2))
    >>> for k in range(1, 3000):
    ...     x[k] = [0.9 * x[k - 1, 0] + rng.standard_normal(), x[k - 1, 0] + 0.2 * rng.standard_normal()]
    >>> cva = CVAResidual.fit(x, lags=2, order=1)
    >>> cva.output_names, cva.past, cva.future
    (['T2s', 'T2r', 'Q'], 2, 2)
    >>> [round(float(s), 3) for s in cva.correlations]     # one state: x0
    [0.997, 0.05, 0.033, 0.002]
    >>> (cva.run_array(x)[0, 2:] > cva.limits).mean(axis=0).round(3).tolist()   # about 1 %
    [0.013, 0.009, 0.009]
    """

    output_units: ClassVar[list[str]] = ["", "", ""]

    def __init__(self, channels: Sequence[str], mean: Any, scale: Any, J: Any, order: int, residual_map: Any,
                 residual_eigenvalues: Any, correlations: Any, *, n_train: int, past: int, future: int,
                 level: float = 0.99, empirical_limits: Any = None, dt: float | None = None):
        self.past, self.future = int(past), int(future)
        if self.past < 1 or self.future < 1:
            raise DataError(f"CVA needs past >= 1 and future >= 1 samples, got {past} and {future}")
        self._init_window(channels, mean, scale, self.past - 1, dt)
        q = self.past * len(self.channels)
        self.J = np.asarray(J, dtype=float)
        self.order = int(order)
        if self.J.shape != (q, q):
            raise DataError(f"J must have shape ({q}, {q}), got {self.J.shape}")
        if not 1 <= self.order < q:
            raise DataError(f"CVA order must lie in 1..{q - 1} (the past vector has dimension {q}), "
                            f"got {order}")
        self.residual_map = np.asarray(residual_map, dtype=float).reshape(q, q)
        self.residual_eigenvalues = np.asarray(residual_eigenvalues, dtype=float).reshape(q)
        self.correlations = np.asarray(correlations, dtype=float).ravel()
        self._Jn = np.ascontiguousarray(self.J[:self.order].T)
        self._Jr = np.ascontiguousarray(self.J[self.order:].T)
        self._R = np.ascontiguousarray(self.residual_map.T)
        self.n_train = int(n_train)
        self.level = float(level)
        self.limits = self.limit(self.level)
        self.empirical_limits = None if empirical_limits is None else \
            np.asarray(empirical_limits, dtype=float).reshape(3)
        self.output_names = ["T2s", "T2r", "Q"]

    # ------------------------------------------------------------------ design
    @classmethod
    def fit(cls, data: Any, *, channels: Sequence[str] | None = None, lags: int | None = None,
            future: int | None = None, order: int | str | None = "heldout", variance: float = 0.9,
            max_lags: int = 10, level: float = 0.99, holdout: float = 0.3) -> CVAResidual:
        """Fit the model on nominal data.

        Parameters
        ----------
        data : Signals or array_like (T, m) or (runs, T, m)
            Nominal training data (each run gives its own vectors).
        channels : sequence of str, optional
            Channels to monitor (default: all; for an array, the names of its columns).
        lags : int, optional
            Samples ``p`` in the past vector (the current one included); default: the order of
            :func:`~fdikit.residuals.datadriven.select_lags` (AIC, Russell et al. 2000).
        future : int, optional
            Samples ``f`` in the future vector (default ``p``).
        order : int, "heldout" or "variance"
            Number of states. ``"heldout"`` (default; also None): the order whose states best
            predict the future vectors of a held-out block (:func:`heldout_order`: the model fitted
            on the first ``1 - holdout`` of each run, the prediction error measured on the rest,
            then refitted on everything). ``"variance"``: the fewest canonical correlations whose
            squares make up ``variance`` of their sum (the former default; on the Tennessee
            Eastman set ``d00`` with 2 lags it keeps 55 of 104 states, and the T² limits of so
            many states alarm on 16-18 % of the nominal test set).
        variance : float
            See ``order``.
        holdout : float
            Held-out fraction of each run for ``order="heldout"``.
        max_lags : int
            Largest order tried when ``lags`` is None.
        level : float
            Confidence level of the control limits.

        Returns
        -------
        CVAResidual

        Raises
        ------
        DataError
            A non-finite or constant channel (named), too few samples for the vector dimension,
            singular past or future covariances (collinear channels), or a bad order.
        """
        values, names, dt = training_data(data, channels)
        mean, scale = fit_scaling(values, names)
        z = (values - mean) / scale
        p = select_lags(z, max_lags) if lags is None else int(lags)
        f = p if future is None else int(future)
        if p < 1 or f < 1:
            raise DataError(f"CVA needs lags >= 1 and future >= 1 samples, got {p} and {f}")
        m = len(names)
        q = p * m
        rows = [lagged(zr, p + f - 1) for zr in z if zr.shape[0] >= p + f]
        n = sum(r.shape[0] for r in rows)
        check_enough(n, max(p, f) * m, cls.__name__, runs=z.shape[0], samples=z.shape[1],
                     lags=f"(past {p}, future {f})")
        W = np.concatenate(rows)
        P = W[:, f * m:]                        # newest first: z_{k+f} .. z_{k+1} | z_k .. z_{k-p+1}
        Spp, _, sigma, J = _canonical(W, f, m)
        if order is None or order == "heldout":
            k = heldout_order(z, p, f, holdout)
        elif order == "variance":
            if not 0.0 < float(variance) <= 1.0:
                raise DataError(f"variance must lie in (0, 1], got {variance}")
            frac = np.cumsum(sigma ** 2) / np.sum(sigma ** 2)
            k = min(int(np.searchsorted(frac, float(variance) - 1e-12)) + 1, q - 1)
        elif isinstance(order, str):
            raise DataError(f"order must be an int, 'heldout' or 'variance', got {order!r}")
        else:
            k = int(order)
            if not 1 <= k < q:
                raise DataError(f"CVA order must lie in 1..{q - 1} (the past vector has dimension {q}), "
                                f"got {order}")
        Rmap = np.eye(q) - Spp @ J[:k].T @ J[:k]
        Rtr = P @ Rmap.T
        reig = np.clip(np.linalg.eigvalsh(Rtr.T @ Rtr / (n - 1))[::-1], 0.0, None)
        gen = cls(names, mean, scale, J, k, Rmap, reig, sigma, n_train=n, past=p, future=f, level=level,
                  dt=dt)
        st = gen._statistics(P)
        gen.empirical_limits = np.array([empirical_limit(st[:, i], level) for i in range(3)])
        return gen

    def limit(self, level: float | None = None) -> np.ndarray:
        """Theoretical control limits ``[T2s, T2r, Q]`` at ``level`` (default: the model's)."""
        level = self.level if level is None else float(level)
        q = self.J.shape[0]
        # Russell, Chiang & Braatz 2000: F limits with n and q - n degrees of freedom
        return np.array([t2_limit(self.order, self.n_train, level),
                         t2_limit(q - self.order, self.n_train, level),
                         q_limit(self.residual_eigenvalues, level)])

    # ------------------------------------------------------------------ runtime
    def _statistics(self, V: np.ndarray) -> np.ndarray:
        xs = V @ self._Jn
        xr = V @ self._Jr
        r = V @ self._R
        return np.stack([np.sum(xs * xs, axis=1), np.sum(xr * xr, axis=1), np.sum(r * r, axis=1)], axis=1)

    # ------------------------------------------------------------------ artifacts
    def to_dict(self) -> dict[str, Any]:
        """The fitted model as plain data (arrays stay arrays; see :mod:`fdikit.base.artifacts`)."""
        return {"channels": list(self.channels), "mean": self.mean.copy(), "scale": self.scale.copy(),
                "J": self.J.copy(), "order": self.order, "residual_map": self.residual_map.copy(),
                "residual_eigenvalues": self.residual_eigenvalues.copy(),
                "correlations": self.correlations.copy(), "n_train": self.n_train, "past": self.past,
                "future": self.future, "level": self.level,
                "empirical_limits": None if self.empirical_limits is None else self.empirical_limits.copy(),
                "dt": self.train_dt}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> CVAResidual:
        """Rebuild from :meth:`to_dict`."""
        return cls(d["channels"], d["mean"], d["scale"], d["J"], int(d["order"]), d["residual_map"],
                   d["residual_eigenvalues"], d["correlations"], n_train=int(d["n_train"]),
                   past=int(d["past"]), future=int(d["future"]), level=float(d["level"]),
                   empirical_limits=d.get("empirical_limits"), dt=d.get("dt"))
