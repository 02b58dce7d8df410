"""The densities of the MHSSPT's hypotheses: the uniform-mean Gaussian of ng-chen-speyer
(:class:`UniformMeanGaussian`) and its multivariate, full-covariance form along a mean
segment (:class:`LineMeanGaussian`), evaluated in numpy.
"""

from __future__ import annotations

import numpy as np
from scipy.special import log_ndtr

from ...errors import DataError

__all__ = ["LineMeanGaussian", "UniformMeanGaussian"]


_LOG_SQRT_2PI = 0.5 * np.log(2 * np.pi)


def _log_diff_ndtr(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """log(Phi(u) - Phi(v)) for u > v, accurate in both tails."""
    # upper tail (v > 0): Phi(u) - Phi(v) = Phi(-v) - Phi(-u)
    upper = v > 0
    hi = np.where(upper, -v, u)
    lo = np.where(upper, -u, v)
    lhi, llo = log_ndtr(hi), log_ndtr(lo)
    return lhi + np.log1p(-np.exp(np.minimum(llo - lhi, 0.0)))


class UniformMeanGaussian:
    """Density of a residual vector whose components are Gaussian with an unknown mean that is
    uniformly distributed on ``[low_c, high_c]`` (ng-chen-speyer, Section IV-E)::

        f(x) = prod_c [Phi((x_c - a_c)/s_c) - Phi((x_c - b_c)/s_c)] / (b_c - a_c)

    ``a_c == b_c`` falls back to the Gaussian density with mean ``a_c``.

    Parameters
    ----------
    low, high, std : array_like (C,)
        Mean range and standard deviation of each component (std > 0, high >= low).

    Examples
    --------
    >>> d = UniformMeanGaussian([0.0], [0.0], [1.0])
    >>> round(float(d.logpdf([0.0])), 6)      # log of the standard normal density at 0
    -0.918939
    """

    def __init__(self, low, high, std):
        self.low = np.atleast_1d(np.asarray(low, float))
        self.high = np.atleast_1d(np.asarray(high, float))
        self.std = np.atleast_1d(np.asarray(std, float))
        if not (self.low.shape == self.high.shape == self.std.shape) or self.low.ndim != 1:
            raise DataError(f"low, high and std must be 1-D of equal length, got shapes "
                            f"{self.low.shape}, {self.high.shape}, {self.std.shape}")
        if not (np.all(np.isfinite(self.low)) and np.all(np.isfinite(self.high))
                and np.all(np.isfinite(self.std))):
            raise DataError("density parameters must be finite")
        if np.any(self.std <= 0):
            raise DataError(f"std must be positive, got {self.std.tolist()}")
        if np.any(self.high < self.low):
            c = int(np.argmax(self.high < self.low))
            raise DataError(f"component {c}: high {self.high[c]} < low {self.low[c]}")
        self._point = (self.high - self.low) <= 1e-12 * np.maximum(1.0, np.abs(self.high))

    @property
    def size(self) -> int:
        return self.low.size

    def logpdf(self, x) -> np.ndarray:
        """Log density of ``x`` shaped (..., C), summed over the components -> (...)."""
        x = np.asarray(x, float)
        if x.shape[-1] != self.size:
            raise DataError(f"density has {self.size} components, sample has {x.shape[-1]}")
        s = self.std
        gauss = -0.5 * ((x - self.low) / s) ** 2 - np.log(s) - _LOG_SQRT_2PI
        width = np.where(self._point, 1.0, self.high - self.low)
        with np.errstate(divide="ignore", invalid="ignore"):  # point components are not used
            unif = _log_diff_ndtr((x - self.low) / s, (x - self.high) / s) - np.log(width)
        return np.where(self._point, gauss, unif).sum(axis=-1)

    def to_dict(self) -> dict:
        return {"low": self.low.tolist(), "high": self.high.tolist(), "std": self.std.tolist()}


class LineMeanGaussian:
    """Multivariate Gaussian density with full covariance whose mean is unknown and uniformly
    distributed on the segment from ``a`` to ``b`` (the multivariate form of
    :class:`UniformMeanGaussian`: a fault of unknown size moves the mean along its direction).

    With ``Sigma = L L'``, ``z = L^-1 (x - a)``, ``v = L^-1 (b - a)``, ``w = |v|``, ``u = v / w``
    and ``t = u' z``, integrating the mean out gives::

        f(x) = N(z - t u; 0, I) / |L| * [Phi(t) - Phi(t - w)] / w

    (in one dimension exactly :class:`UniformMeanGaussian`); ``a == b`` is the Gaussian density.

    Parameters
    ----------
    a, b : array_like (C,)
        Ends of the mean segment.
    cov : array_like (C, C)
        Covariance (symmetric positive definite).

    Examples
    --------
    >>> d = LineMeanGaussian([0.0], [2.0], [[1.0]])
    >>> u = UniformMeanGaussian([0.0], [2.0], [1.0])
    >>> bool(abs(d.logpdf([0.7]) - u.logpdf([0.7])) < 1e-12)
    True
    """

    def __init__(self, a, b, cov):
        self.a = np.atleast_1d(np.asarray(a, float))
        self.b = np.atleast_1d(np.asarray(b, float))
        self.cov = np.atleast_2d(np.asarray(cov, float))
        C = self.a.size
        if self.a.ndim != 1 or self.b.shape != (C,) or self.cov.shape != (C, C):
            raise DataError(f"a, b must be (C,) and cov (C, C); got {self.a.shape}, {self.b.shape}, "
                            f"{self.cov.shape}")
        if not all(np.all(np.isfinite(v)) for v in (self.a, self.b, self.cov)):
            raise DataError("density parameters must be finite")
        try:
            self._L = np.linalg.cholesky(0.5 * (self.cov + self.cov.T))
        except np.linalg.LinAlgError:
            ev = np.linalg.eigvalsh(0.5 * (self.cov + self.cov.T))
            raise DataError(f"covariance is not positive definite (smallest eigenvalue {ev.min():.3g})") \
                from None
        self._Linv = np.linalg.inv(self._L)
        v = self._Linv @ (self.b - self.a)
        self._w = float(np.linalg.norm(v))
        self._u = v / self._w if self._w > 1e-12 else np.zeros(C)
        self._logdet = float(np.sum(np.log(np.diag(self._L))))

    @property
    def size(self) -> int:
        return self.a.size

    def logpdf(self, x) -> np.ndarray:
        """Log density of ``x`` shaped (..., C) -> (...)."""
        x = np.asarray(x, float)
        if x.shape[-1] != self.size:
            raise DataError(f"density has {self.size} components, sample has {x.shape[-1]}")
        C = self.size
        d = x - self.a
        # elementwise sums in a fixed order (no BLAS): one sample gives the bits of a whole record
        z = [sum(self._Linv[i, j] * d[..., j] for j in range(i + 1)) for i in range(C)]  # L^-1 lower
        zz = sum(zi * zi for zi in z)
        if self._w <= 1e-12:
            return -0.5 * zz - self._logdet - C * _LOG_SQRT_2PI
        t = sum(self._u[i] * z[i] for i in range(C))
        perp2 = np.maximum(zz - t * t, 0.0)
        return (-0.5 * perp2 - (C - 1) * _LOG_SQRT_2PI - self._logdet
                + _log_diff_ndtr(t, t - self._w) - np.log(self._w))

    def to_dict(self) -> dict:
        return {"a": self.a.tolist(), "b": self.b.tolist(), "cov": self.cov.tolist()}
