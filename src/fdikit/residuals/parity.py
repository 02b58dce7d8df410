"""Signal conditioning for parity-equation residuals: low-pass filtering and derivatives.

Parity equations (luo-et-al, Section V-A) need time derivatives of sampled, noisy
measurements. The paper low-passes the measurements with a tenth-order Butterworth filter at
10 Hz and takes derivatives from a cubic smoothing-spline regression. Each operation here comes
in two variants, and which one is **online-capable** is stated on each function:

==============================  ===============================  ==================================
operation                        online (causal, streaming)       offline (zero-phase, whole record)
==============================  ===============================  ==================================
Butterworth low-pass             :func:`lowpass` (``sosfilt``)     :func:`lowpass` ``zero_phase=True``
                                 and :class:`CausalLowPass`        (``sosfiltfilt``)
smoothing-spline derivative      :func:`causal_spline_derivative`  :func:`spline_derivative`
                                 and :class:`CausalDerivative`     (one spline over the record)
==============================  ===============================  ==================================

The causal spline derivative fits a cubic smoothing spline to the last ``window`` samples and
differentiates it at the newest sample. With a fixed smoothing parameter the spline is linear in
the data, so that fit is exactly a FIR filter whose taps :func:`spline_derivative_weights`
computes once (by fitting the spline to the unit vectors); applying the taps is the same
number as refitting the spline at every sample (a test checks it) and costs ``window``
multiply-adds per sample.

Smoothing parameter: the penalised criterion ``sum_i (y_i - f(t_i))^2 + lam * int f''(t)^2 dt``
on a uniform grid of step ``dt`` behaves like a low-pass with gain ``1 / (1 + lam dt w^4)``
(Reinsch 1967; Silverman 1984, equivalent kernel), i.e. a half-power angular frequency
``w_c = (lam dt)^(-1/4)``. :func:`spline_lam` turns a cut-off frequency in Hz into ``lam``.

Start of a record: the causal filters start in steady state at the first sample (as if the
signal had been constant before it: ``sosfilt_zi`` scaled by the first sample, and the
derivative window padded with copies of the first sample), so no start-up transient appears.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.interpolate import make_smoothing_spline
from scipy.signal import butter, sosfilt, sosfilt_zi, sosfiltfilt

from ..base.state import Stateful
from ..errors import DataError

__all__ = [
    "CausalDerivative",
    "CausalLowPass",
    "butter_sos",
    "causal_spline_derivative",
    "lowpass",
    "spline_derivative",
    "spline_derivative_weights",
    "spline_lam",
]


def _check_finite(x: np.ndarray, what: str) -> None:
    bad = ~np.isfinite(x)
    if bad.any():
        idx = tuple(int(i) for i in np.argwhere(bad)[0])
        raise DataError(f"{what} has a non-finite value {x[idx]} at index {idx}")


def butter_sos(order: int = 10, cutoff_hz: float = 10.0, fs_hz: float = 100.0) -> np.ndarray:
    """Butterworth low-pass in second-order sections (luo-et-al, Section V-A: 10th order, 10 Hz).

    Parameters
    ----------
    order : int
        Filter order (>= 1).
    cutoff_hz : float
        -3 dB frequency, Hz; below the Nyquist frequency ``fs_hz / 2``.
    fs_hz : float
        Sampling frequency, Hz (100 Hz for the 10 ms ABS samples).

    Returns
    -------
    ndarray (ceil(order/2), 6)
        Second-order sections for :func:`scipy.signal.sosfilt`.

    Examples
    --------
    >>> butter_sos().shape
    (5, 6)
    """
    if int(order) != order or order < 1:
        raise DataError(f"Butterworth order must be an integer >= 1, got {order}")
    if not 0 < cutoff_hz < fs_hz / 2:
        raise DataError(f"cut-off {cutoff_hz} Hz must lie in (0, {fs_hz / 2}) (Nyquist of fs = {fs_hz} Hz)")
    return butter(int(order), cutoff_hz, btype="low", fs=fs_hz, output="sos")


def lowpass(x, sos: np.ndarray, *, axis: int = -1, zero_phase: bool = False) -> np.ndarray:
    """Low-pass ``x`` along ``axis`` with second-order sections ``sos``.

    ``zero_phase=False`` (default) is **online-capable**: causal ``sosfilt`` started in steady
    state at the first sample (equals :class:`CausalLowPass` sample by sample).
    ``zero_phase=True`` is **offline only**: forward-backward ``sosfiltfilt`` (no delay, the
    squared magnitude response, needs the whole record).

    Parameters
    ----------
    x : array_like
        Signal, any shape; filtered along ``axis``.
    sos : ndarray (n_sections, 6)
        From :func:`butter_sos`.

    Returns
    -------
    ndarray, shape of ``x``

    Examples
    --------
    >>> import numpy as np
    >>> y = lowpass(np.full(50, 3.0), butter_sos())
    >>> bool(np.allclose(y, 3.0))
    True
    """
    x = np.asarray(x, float)
    _check_finite(x, "low-pass input")
    if zero_phase:
        padlen = 3 * (2 * len(sos) + 1)
        if x.shape[axis] <= padlen:
            raise DataError(f"zero-phase filtering needs more than {padlen} samples, got {x.shape[axis]}")
        return sosfiltfilt(sos, x, axis=axis)
    xm = np.moveaxis(x, axis, -1)
    zi = sosfilt_zi(sos)  # (n_sections, 2), unit step steady state
    zi = zi.reshape((zi.shape[0],) + (1,) * (xm.ndim - 1) + (2,)) * xm[..., :1][None]
    y, _ = sosfilt(sos, xm, axis=-1, zi=zi)
    return np.moveaxis(y, -1, axis)


class CausalLowPass(Stateful):
    """Streaming form of :func:`lowpass` (causal): one sample of shape ``(runs, channels)`` per step.

    Examples
    --------
    >>> import numpy as np
    >>> f = CausalLowPass(butter_sos(4, 10.0, 100.0))
    >>> f.reset(1, 1)
    >>> out = [f.step(np.array([[2.0]]))[0, 0] for _ in range(3)]
    >>> bool(np.allclose(out, 2.0))
    True
    """

    def __init__(self, sos: np.ndarray):
        self.sos = np.asarray(sos, float)
        self._zi_unit = sosfilt_zi(self.sos)
        self._z: np.ndarray | None = None

    _state_attrs = ("_z", "_shape")

    def reset(self, runs: int = 1, channels: int = 1) -> None:
        self._z = None
        self._shape = (runs, channels)

    def step(self, x_k: np.ndarray) -> np.ndarray:
        x = np.asarray(x_k, float).reshape(self._shape)
        _check_finite(x, "low-pass input sample")
        if self._z is None:  # steady state at the first sample
            self._z = self._zi_unit[:, None, None, :] * x[None, :, :, None]
        y, self._z = sosfilt(self.sos, x[:, :, None], axis=-1, zi=self._z)
        return y[:, :, 0]


def spline_lam(cutoff_hz: float, dt: float) -> float:
    """Smoothing parameter of a cubic smoothing spline with half-power frequency ``cutoff_hz``.

    ``lam = 1 / (dt * (2 pi f_c)^4)`` for the criterion ``sum (y_i - f(t_i))^2 + lam int f''^2``
    on a uniform grid of step ``dt`` seconds (equivalent-kernel gain ``1/(1 + lam dt w^4)``).

    Examples
    --------
    >>> f"{spline_lam(10.0, 0.01):.3e}"
    '6.416e-06'
    """
    if cutoff_hz <= 0 or dt <= 0:
        raise DataError(f"spline cut-off ({cutoff_hz} Hz) and dt ({dt} s) must be positive")
    return 1.0 / (dt * (2.0 * math.pi * cutoff_hz) ** 4)


def spline_derivative_weights(window: int, dt: float, lam: float, order: int = 1) -> np.ndarray:
    """FIR taps of the causal smoothing-spline derivative (newest sample last).

    ``w @ x[k-window+1 : k+1]`` is the ``order``-th derivative, at ``t_k``, of the cubic smoothing
    spline (:func:`scipy.interpolate.make_smoothing_spline`, fixed ``lam``) fitted to the last
    ``window`` samples. Exact because the fit is linear in the data: the taps are the fit to
    the unit vectors.

    Parameters
    ----------
    window : int
        Samples in the sliding window (>= 5, scipy's minimum for a smoothing spline).
    dt : float
        Sample interval, s.
    lam : float
        Smoothing parameter (>= 0), see :func:`spline_lam`.
    order : int
        Derivative order, 0..3 (a cubic has no 4th derivative).

    Returns
    -------
    ndarray (window,)
        Taps in units of 1/s^order.

    Examples
    --------
    >>> import numpy as np
    >>> w = spline_derivative_weights(10, 0.01, 1e-6)
    >>> round(float(w @ (0.01 * np.arange(10) * 3.0)), 9)   # slope of a line
    3.0
    """
    if int(window) != window or window < 5:
        raise DataError(f"spline window must be an integer >= 5 samples, got {window}")
    if int(order) != order or not 0 <= order <= 3:
        raise DataError(f"derivative order must be 0..3, got {order}")
    if lam < 0 or dt <= 0:
        raise DataError(f"lam ({lam}) must be >= 0 and dt ({dt}) > 0")
    t = np.arange(int(window)) * float(dt)
    spl = make_smoothing_spline(t, np.eye(int(window)), lam=float(lam))
    d = spl.derivative(int(order)) if order else spl
    return np.asarray(d(t[-1]), float)


def causal_spline_derivative(x, dt: float, *, window: int, lam: float, order: int = 1,
                             axis: int = -1) -> np.ndarray:
    """Causal (**online-capable**) smoothing-spline derivative along ``axis``.

    Sample ``k`` uses samples ``k-window+1..k`` only; before the window is full it is padded
    with copies of the first sample. Equals :class:`CausalDerivative` sample by sample.

    Returns
    -------
    ndarray, shape of ``x``, units of x per s^order.

    Examples
    --------
    >>> import numpy as np
    >>> t = np.arange(100) * 0.01
    >>> d = causal_spline_derivative(2.0 * t, 0.01, window=20, lam=1e-6)
    >>> round(float(d[-1]), 6)
    2.0
    """
    x = np.asarray(x, float)
    _check_finite(x, "derivative input")
    w = spline_derivative_weights(window, dt, lam, order)
    xm = np.moveaxis(x, axis, -1)
    if xm.shape[-1] < 1:
        raise DataError("derivative of an empty record")
    pad = np.repeat(xm[..., :1], window - 1, axis=-1)
    xp = np.concatenate([pad, xm], axis=-1)
    from numpy.lib.stride_tricks import sliding_window_view

    out = sliding_window_view(xp, window, axis=-1) @ w
    return np.moveaxis(out, -1, axis)


class CausalDerivative(Stateful):
    """Streaming form of :func:`causal_spline_derivative`: ``step(x_k (runs, channels))``.

    Examples
    --------
    >>> import numpy as np
    >>> d = CausalDerivative(window=10, dt=0.01, lam=1e-6)
    >>> d.reset(1, 1)
    >>> vals = [d.step(np.array([[0.5 * k * 0.01]]))[0, 0] for k in range(12)]
    >>> round(float(vals[-1]), 6)
    0.5
    """

    def __init__(self, window: int, dt: float, lam: float, order: int = 1):
        self.w = spline_derivative_weights(window, dt, lam, order)
        self.window = int(window)
        self._buf: np.ndarray | None = None

    _state_attrs = ("_buf", "_shape")

    def reset(self, runs: int = 1, channels: int = 1) -> None:
        self._buf = None
        self._shape = (runs, channels)

    def step(self, x_k: np.ndarray) -> np.ndarray:
        x = np.asarray(x_k, float).reshape(self._shape)
        _check_finite(x, "derivative input sample")
        if self._buf is None:
            self._buf = np.repeat(x[:, :, None], self.window, axis=2)
        else:
            self._buf[:, :, :-1] = self._buf[:, :, 1:]
            self._buf[:, :, -1] = x
        return self._buf @ self.w


def spline_derivative(x, dt: float, *, lam: float | None = None, order: int = 1,
                      axis: int = -1) -> np.ndarray:
    """Zero-phase (**offline only**) derivative: one smoothing spline over the whole record.

    Parameters
    ----------
    x : array_like
        Samples on a uniform grid of step ``dt`` along ``axis`` (at least 5).
    lam : float or None
        Smoothing parameter; None chooses it by generalised cross-validation per series
        (scipy's default), which makes the operation data dependent (and slow for many runs).
    order : int
        Derivative order 0..3.

    Returns
    -------
    ndarray, shape of ``x``

    Examples
    --------
    >>> import numpy as np
    >>> t = np.arange(50) * 0.01
    >>> d = spline_derivative(np.sin(t), 0.01, lam=1e-8)
    >>> bool(np.allclose(d[5:-5], np.cos(t[5:-5]), atol=1e-4))
    True
    """
    x = np.asarray(x, float)
    _check_finite(x, "derivative input")
    if int(order) != order or not 0 <= order <= 3:
        raise DataError(f"derivative order must be 0..3, got {order}")
    xm = np.moveaxis(x, axis, -1)
    n = xm.shape[-1]
    if n < 5:
        raise DataError(f"a smoothing spline needs at least 5 samples, got {n}")
    t = np.arange(n) * float(dt)
    flat = xm.reshape(-1, n)
    if lam is not None:  # one linear fit for every series at once
        spl = make_smoothing_spline(t, flat.T, lam=float(lam))
        out = (spl.derivative(order) if order else spl)(t).T
    else:
        out = np.empty_like(flat)
        for i, row in enumerate(flat):
            spl = make_smoothing_spline(t, row)
            out[i] = (spl.derivative(order) if order else spl)(t)
    return np.moveaxis(out.reshape(xm.shape), -1, axis)
