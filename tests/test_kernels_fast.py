"""The fast compiled kernels against plain numpy / scipy reference implementations (issue 19).

* The fault detection filter multiplies only the structural nonzeros of ``[[C, Dv], [A, Bv]]``:
  on random block-diagonal (stacked) and dense designs it equals the dense numpy recursion, and
  batch equals streaming bitwise.
* The uniform-mean Gaussian component density (direct ``Phi(hi) - Phi(lo)`` inside the erfc range,
  the log form in the far tails) equals scipy's ``log(ndtr(u) - ndtr(v)) - log(w)``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.special import log_ndtr, ndtr

from fdikit.detect.mhsspt import umg_component_logpdf
from fdikit.residuals import FaultDetectionFilter, FilterDesign, stack_designs
from fdikit.signals import Signals


def _random_design(rng, nf, m_u, m_y, q, dt=0.02, sparse=0.0, tag=""):
    A = rng.normal(size=(nf, nf))
    A *= 0.9 / max(1e-9, np.max(np.abs(np.linalg.eigvals(A)))) if nf else 1.0
    Bu, By = rng.normal(size=(nf, m_u)), rng.normal(size=(nf, m_y))
    C, Du, Dy = rng.normal(size=(q, nf)), rng.normal(size=(q, m_u)), rng.normal(size=(q, m_y))
    for M in (Bu, By, C, Du, Dy):
        M[rng.random(M.shape) < sparse] = 0.0
    return FilterDesign(A, Bu, By, C, Du, Dy, dt, [f"u{i}" for i in range(m_u)],
                        [f"y{i}" for i in range(m_y)], [f"r{tag}{i}" for i in range(q)])


def _dense_reference(d: FilterDesign, u: np.ndarray, y: np.ndarray) -> np.ndarray:
    """r_k = C x_k + Du u_k + Dy y_k, x_(k+1) = A x_k + Bu u_k + By y_k (numpy, per run)."""
    R, T = u.shape[:2]
    out = np.empty((R, T, d.C.shape[0]))
    for r in range(R):
        x = np.zeros(d.order)
        for k in range(T):
            out[r, k] = d.C @ x + d.Du @ u[r, k] + d.Dy @ y[r, k]
            x = d.A @ x + d.Bu @ u[r, k] + d.By @ y[r, k]
    return out


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("stacked", [False, True])
def test_sparse_filter_equals_dense_numpy_and_stream(seed, stacked):
    rng = np.random.default_rng(seed)
    m_u, m_y = 2, 3
    if stacked:
        d = stack_designs([_random_design(rng, int(rng.integers(0, 6)), m_u, m_y, 2, sparse=0.3, tag=f"{b}_")
                           for b in range(4)])
    else:
        d = _random_design(rng, 5, m_u, m_y, 3)
    R, T = 2, 300
    u, y = rng.normal(size=(R, T, m_u)), rng.normal(size=(R, T, m_y))
    sig = Signals(np.arange(T) * d.dt, np.concatenate([u, y], axis=2), d.u_names + d.y_names)
    f = FaultDetectionFilter(d)
    batch = f.run(sig).values
    ref = _dense_reference(d, u, y)
    np.testing.assert_allclose(batch, ref, rtol=1e-12, atol=1e-12 * np.max(np.abs(ref)))
    f.reset(R)
    stream = np.stack([f.step(u[:, k], y[:, k]) for k in range(T)], axis=1)
    assert np.array_equal(stream, batch)
    if stacked:
        nz = np.count_nonzero(np.block([[d.C, d.Du, d.Dy], [d.A, d.Bu, d.By]]))
        assert f._rows[1].size == nz


def _umg_reference(x, low, high, std):
    u, v = (x - low) / std, (x - high) / std
    if v > 0:
        u, v = -v, -u
    # log(Phi(u) - Phi(v)) in the log form for the far tail, the difference elsewhere
    if u < -30:
        lu, lv = log_ndtr(u), log_ndtr(v)
        return lu + math.log1p(-math.exp(lv - lu)) - math.log(high - low)
    return math.log(ndtr(u) - ndtr(v)) - math.log(high - low)


@pytest.mark.parametrize("low, high, std", [(-0.5, 0.7, 0.4), (0.0, 0.05, 1.0), (0.1, 5.0, 0.05),
                                            (-1.0, 1.0, 3.0)])
def test_umg_component_density_equals_scipy(low, high, std):
    xs = np.concatenate([np.linspace(low - 60 * std, high + 60 * std, 2001),
                         np.random.default_rng(0).normal(low, 5 * std, 500)])
    lw = math.log(high - low)
    got = np.array([umg_component_logpdf(x, low, high, std, False, lw) for x in xs])
    ref = np.array([_umg_reference(x, low, high, std) for x in xs])
    assert np.all(np.isfinite(got))
    np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-12)


def test_umg_point_component_is_gaussian():
    for x in (-3.0, 0.0, 0.7, 12.0):
        got = umg_component_logpdf(x, 0.5, 0.5, 0.3, True, 0.0)
        ref = -0.5 * ((x - 0.5) / 0.3) ** 2 - math.log(0.3) - 0.5 * math.log(2 * math.pi)
        assert got == pytest.approx(ref, rel=1e-14)
