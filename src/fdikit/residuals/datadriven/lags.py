"""Lagged (Hankel) vectors of scaled samples, the choice of the number of lags, and the streaming
window that the data-driven residual generators share.

A data-driven detector reads, at sample ``k``, the window of the last ``lags + 1`` scaled samples
stacked newest first, ``v_k = [z_k; z_{k-1}; ...; z_{k-lags}]`` (``z`` = channel minus its mean,
divided by its standard deviation). Static PCA has ``lags = 0``; dynamic PCA and CVA use more.

:class:`LaggedStatistic` is the runtime part they share: ``run(signals)`` builds every window of
a record at once, ``reset``/``step`` keeps the last ``lags`` samples in a buffer (its streaming
state) and both hand the windows to the subclass's ``_statistics``. Before ``lags`` samples
have been seen, the window is filled with copies of the first sample (the record is taken to
have been steady before it started), so the first ``lags`` outputs are a warm-up
(``warmup_samples``; a :class:`~fdikit.monitor.Monitor` reads ``settling_time``).

:func:`select_lags` chooses the number of lags as Russell, Chiang & Braatz (2000) do: the order
of a vector autoregressive model of the scaled data that minimises Akaike's information
criterion (its small-sample form).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from ...base.stage import ResidualGenerator
from ...errors import DataError
from ...signals import Signals, check_finite

__all__ = ["LaggedStatistic", "lagged", "select_lags"]


def lagged(z: np.ndarray, lags: int) -> np.ndarray:
    """Every full window of ``lags + 1`` samples of one record, newest sample first.

    Parameters
    ----------
    z : ndarray (T, m)
        Samples of one run.
    lags : int
        Past samples in each window (>= 0).

    Returns
    -------
    ndarray (T - lags, (lags + 1) m)
        Row ``i`` is ``[z[i+lags], z[i+lags-1], ..., z[i]]``.

    Examples
    --------
    >>> import numpy as np
    >>> lagged(np.arange(4.0)[:, None], 1).tolist()
    [[1.0, 0.0], [2.0, 1.0], [3.0, 2.0]]
    """
    T = z.shape[0]
    n = T - lags
    if n < 1:
        raise DataError(f"a window of {lags + 1} samples needs at least that many samples, got {T}")
    return np.concatenate([z[lags - j:lags - j + n] for j in range(lags + 1)], axis=1)


def select_lags(values: Sequence[np.ndarray] | np.ndarray, max_lags: int = 10) -> int:
    """Number of lags by Akaike's criterion for a vector autoregressive model (Russell et al. 2000).

    For ``h = 1 .. max_lags`` the model ``z_k = A_1 z_{k-1} + ... + A_h z_{k-h} + e_k`` is fitted
    by least squares on the same samples (those with ``max_lags`` predecessors, of every run), and
    scored by the small-sample criterion of Hurvich & Tsai (1993),
    ``AICc(h) = N log det(S_h) + N m (N + h m) / (N - h m - m - 1)``, with ``S_h`` the residual
    covariance over ``N`` samples. (The plain AIC ``N log det S_h + 2 h m²`` keeps falling when
    ``h m`` nears ``N``, as with 52 channels and 500 samples, and picks the largest order tried.)
    Orders with ``h m + m + 1 >= N`` are not tried.

    Parameters
    ----------
    values : ndarray (T, m) or (runs, T, m), or a list of (T_i, m) arrays
        Scaled (zero-mean) training data.
    max_lags : int
        Largest order tried.

    Returns
    -------
    int
        The order with the smallest AICc (>= 1).

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> z = np.zeros((2000, 2))
    >>> for k in range(2, 2000):
    ...     z[k] = 0.5 * z[k - 1] - 0.4 * z[k - 2] + rng.standard_normal(2)
    >>> select_lags(z, 5)
    2
    """
    runs = [values] if isinstance(values, np.ndarray) and values.ndim == 2 else list(values)
    m = runs[0].shape[1]
    max_lags = int(max_lags)
    if max_lags < 1:
        raise DataError(f"max_lags must be >= 1, got {max_lags}")
    best, best_aic = None, np.inf
    rows = [lagged(z, max_lags) for z in runs if z.shape[0] > max_lags]
    V = np.concatenate(rows) if rows else np.zeros((0, (max_lags + 1) * m))
    N = V.shape[0]
    h_max = min(max_lags, (N - m - 2) // m)         # orders with N - h m - m - 1 > 0
    if h_max >= 1:
        Y = V[:, :m]
        # one QR of the regressors of the largest order: the first h m columns of Q span those
        # of order h, so every order's residual is Y less its projection on them
        Q, _ = np.linalg.qr(V[:, m:(h_max + 1) * m])
        C = Q.T @ Y
        for h in range(1, h_max + 1):
            k = h * m
            E = Y - Q[:, :k] @ C[:k]
            sign, logdet = np.linalg.slogdet(E.T @ E / N)
            if sign <= 0:
                break
            aic = N * logdet + N * m * (N + k) / (N - k - m - 1)     # Hurvich & Tsai 1993
            if aic < best_aic:
                best, best_aic = h, aic
    if best is None:
        raise DataError(f"too few training samples to fit even a first-order autoregressive model of {m} "
                        "channels; give the number of lags")
    return best


class LaggedStatistic(ResidualGenerator):
    """Base of the data-driven residual generators: scaled samples in a window of ``lags + 1``.

    Subclasses set the fitted attributes and implement ``_statistics(V) -> (N, n_out)`` for
    windows ``V`` of shape ``(N, (lags + 1) m)``; batch ``run`` and streaming ``step`` both call
    it (same numbers to rounding; a test checks it). The channels are the measurements
    (``y_names``); there are no known inputs (``u_names`` is empty: a streaming ``step`` takes
    ``u_k`` of shape ``(runs, 0)``, e.g. ``[]`` for one run).
    """

    channels: list[str]
    mean: np.ndarray
    scale: np.ndarray
    lags: int
    train_dt: float | None

    _state_attrs = ("_buf",)

    def _init_window(self, channels: Sequence[str], mean: Any, scale: Any, lags: int,
                     dt: float | None) -> None:
        self.channels = [str(c) for c in channels]
        m = len(self.channels)
        self.mean = np.asarray(mean, dtype=float).reshape(m)
        self.scale = np.asarray(scale, dtype=float).reshape(m)
        ok = np.all(np.isfinite(self.mean)) and np.all(np.isfinite(self.scale)) and np.all(self.scale > 0)
        if not ok:
            raise DataError("channel means must be finite and scales finite and > 0")
        self.lags = int(lags)
        if self.lags < 0:
            raise DataError(f"lags must be >= 0, got {lags}")
        self.train_dt = None if dt is None else float(dt)
        self.u_names = []
        self.y_names = list(self.channels)
        self._buf: np.ndarray | None = None

    # ------------------------------------------------------------------ what a Monitor reads
    @property
    def dt(self) -> float | None:
        """Sample period the lags were learnt at (None without lags: static data have no clock)."""
        return self.train_dt if self.lags else None

    @property
    def warmup_samples(self) -> int:
        """Outputs at the start of a record that still lean on the copied first sample."""
        return self.lags

    @property
    def settling_time(self) -> float | None:
        """``lags * dt`` (s): the warm-up of a :class:`~fdikit.monitor.Monitor`."""
        if not self.lags:
            return 0.0
        return None if self.train_dt is None else self.lags * self.train_dt

    # ------------------------------------------------------------------ runtime
    def _statistics(self, V: np.ndarray) -> np.ndarray:  # pragma: no cover - interface
        raise NotImplementedError

    def reset(self, runs: int = 1) -> None:
        """Forget the window (the next sample is taken as steady before it)."""
        self._buf = None

    def _step(self, u: np.ndarray, y: np.ndarray) -> np.ndarray:
        z = (y - self.mean) / self.scale
        buf = self._buf
        if buf is None or buf.shape[0] != z.shape[0]:
            if buf is not None:
                raise DataError(f"{type(self).__name__}: sample of {z.shape[0]} runs after reset for "
                                f"{buf.shape[0]}; call reset(runs) first")
            buf = self._buf = np.repeat(z[:, None, :], self.lags + 1, axis=1)
        else:
            buf[:, 1:] = buf[:, :-1].copy()
            buf[:, 0] = z
        return self._statistics(buf.reshape(z.shape[0], -1))

    def _values(self, data: Any) -> np.ndarray:
        """``(runs, T, m)`` samples of the channels from Signals or an array (checked)."""
        if isinstance(data, Signals):
            v = data.values[:, :, data.index(self.channels)]
        else:
            v = np.asarray(data, dtype=float)
            if v.ndim == 2:
                v = v[None]
            if v.ndim != 3 or v.shape[2] != len(self.channels):
                raise DataError(f"data must have shape (T, {len(self.channels)}) or (runs, T, "
                                f"{len(self.channels)}) for channels {self.channels}, got {v.shape}")
        check_finite(v, self.channels)
        return v

    def windows(self, data: Any) -> np.ndarray:
        """The windows ``v_k`` of every sample of a record, as ``step`` sees them.

        Parameters
        ----------
        data : Signals or array_like (T, m) or (runs, T, m)

        Returns
        -------
        ndarray (runs, T, (lags + 1) m)
        """
        v = self._values(data)
        z = (v - self.mean) / self.scale
        if self.lags:
            z = np.concatenate([np.repeat(z[:, :1], self.lags, axis=1), z], axis=1)
        return np.stack([lagged(zr, self.lags) for zr in z])

    def run(self, signals: Signals) -> Signals:
        """The statistics over a whole record (all runs at once); leaves the streaming state alone."""
        out = self.run_array(signals)
        return Signals(signals.t, out, self.output_names, self.output_units, check=False)

    def run_array(self, data: Any) -> np.ndarray:
        """:meth:`run` on an array ``(T, m)`` / ``(runs, T, m)`` (or Signals): ``(runs, T, n_out)``."""
        V = self.windows(data)
        runs, T = V.shape[:2]
        return self._statistics(V.reshape(runs * T, -1)).reshape(runs, T, -1)

    def __repr__(self) -> str:
        return (f"{type(self).__name__}(channels={len(self.channels)}, lags={self.lags}, "
                f"outputs={self.output_names}, level={getattr(self, 'level', None)})")
