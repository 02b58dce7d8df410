"""Training data of the data-driven detectors: nominal records checked, named and scaled.

The detectors learn from nominal records given as :class:`~fdikit.signals.Signals` (one or many
runs, channels chosen by name) or as plain arrays ``(T, m)`` / ``(runs, T, m)``. Every record is
checked here, before any fitting, with a :class:`~fdikit.errors.DataError` that names the channel
and the sample: a NaN or inf, a channel that never changes (its standard deviation is zero, so
it cannot be scaled), and too few samples for the lagged dimension being fitted.

Scaling is the usual autoscaling of process monitoring (Chiang, Russell & Braatz 2001, Sec. 4.2):
each channel minus its training mean, divided by its training standard deviation (``ddof=1``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from ...errors import DataError
from ...signals import Signals, check_finite

__all__ = ["check_enough", "fit_scaling", "training_data"]


def training_data(data: Any, channels: Sequence[str] | None = None
                  ) -> tuple[np.ndarray, list[str], float | None]:
    """Nominal training data as ``(runs, T, m)`` floats, their channel names and sample period.

    Parameters
    ----------
    data : Signals or array_like
        A :class:`~fdikit.signals.Signals` record, or an array ``(T, m)`` (one run) or
        ``(runs, T, m)``.
    channels : sequence of str, optional
        Channels to use: names in ``data`` (default: all of them); for an array, the names of its
        ``m`` columns (default ``x0, x1, ...``).

    Returns
    -------
    values : ndarray (runs, T, m)
    names : list of str
    dt : float or None
        The median sample period of a Signals record (None for an array).

    Raises
    ------
    DataError
        A non-finite value (naming channel, run and sample), or a wrong shape.

    Examples
    --------
    >>> import numpy as np
    >>> v, names, dt = training_data(np.zeros((4, 2)))
    >>> v.shape, names, dt
    ((1, 4, 2), ['x0', 'x1'], None)
    """
    if isinstance(data, Signals):
        names = list(data.names) if channels is None else [str(c) for c in channels]
        v = data.values[:, :, data.index(names)]
        dt = float(np.median(np.diff(data.t))) if data.n_samples > 1 else None
    else:
        v = np.asarray(data, dtype=float)
        if v.ndim == 2:
            v = v[None]
        if v.ndim != 3:
            raise DataError(f"training data must have shape (T, m) or (runs, T, m), got {v.shape}")
        names = [f"x{i}" for i in range(v.shape[2])] if channels is None else [str(c) for c in channels]
        if len(names) != v.shape[2]:
            raise DataError(f"training data have {v.shape[2]} channels but {len(names)} names: {names}")
        dt = None
    if not names:
        raise DataError("training data need at least one channel")
    if len(set(names)) != len(names):
        raise DataError(f"duplicated channel names: {sorted({n for n in names if names.count(n) > 1})}")
    check_finite(v, names, what="training")
    return v, names, dt


def fit_scaling(values: np.ndarray, names: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
    """Mean and standard deviation (``ddof=1``) of each channel over all runs and samples.

    Raises
    ------
    DataError
        A channel whose standard deviation is zero (constant in the training data), or
        fewer than two samples.

    Examples
    --------
    >>> import numpy as np
    >>> mean, std = fit_scaling(np.array([[[1.0, 2.0], [3.0, 2.0]]]), ["a", "b"])
    Traceback (most recent call last):
    ...
    fdikit.errors.DataError: channel 'b' is constant (2.0) in the training data: it cannot be scaled; drop it
    """
    flat = values.reshape(-1, values.shape[-1])
    if flat.shape[0] < 2:
        raise DataError(f"scaling needs at least 2 training samples, got {flat.shape[0]}")
    mean = flat.mean(axis=0)
    std = flat.std(axis=0, ddof=1)
    # a spread below rounding of the mean is no spread: the channel is constant
    tiny = std <= 16 * np.finfo(float).eps * np.maximum(np.abs(mean), np.finfo(float).tiny)
    if tiny.any():
        j = int(np.flatnonzero(tiny)[0])
        raise DataError(f"channel {names[j]!r} is constant ({float(flat[0, j])!r}) in the training data: "
                        "it cannot be scaled; drop it")
    return mean, std


def check_enough(n_vectors: int, dim: int, what: str, *, runs: int, samples: int, lags: str) -> None:
    """Refuse training data with no more lagged vectors than their dimension.

    A covariance of ``dim`` variables estimated from ``n_vectors <= dim`` vectors is singular,
    so neither its eigenvalues (PCA limits) nor its inverse (CVA) mean anything.
    """
    if n_vectors <= dim:
        raise DataError(f"{what}: {runs} run(s) of {samples} samples give {n_vectors} {lags} vectors of "
                        f"dimension {dim}; at least {dim + 1} are needed (record more nominal data, "
                        "use fewer lags or fewer channels)")
