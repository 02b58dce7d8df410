"""Transformations of a designed linear residual filter (:class:`~fdikit.residuals.FilterDesign`)
that keep its decoupling: whitening of the residual to unit noise covariance, a one-sample delay of
the control feedthrough (digital control), and a Butterworth low-pass on every residual."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ..errors import DataError, ModelError
from .fdf import FilterDesign

__all__ = ["band_limited", "delayed_feedthrough", "whiten_design"]


def whiten_design(design: FilterDesign, noise_std: Mapping[str, float], *,
                  rtol: float = 1e-9) -> FilterDesign:
    """The same filter with its residual scaled to unit measurement-noise covariance.

    The residual of a filter driven by white measurement noise of standard deviation ``noise_std``
    on each of its measurements ``y`` has the steady-state covariance
    ``Sigma = C X C' + Dy S^2 Dy'`` with ``X = A X A' + By S^2 By'`` (discrete Lyapunov equation,
    ``S = diag(noise_std)``). The returned filter outputs ``W r`` with the symmetric
    pseudo-inverse square root ``W = V diag(w^-1/2) V'`` over the eigenpairs ``(w, V)`` of
    ``Sigma`` above ``rtol`` times the largest (a UIO residual lives in a subspace of dimension
    ``p`` minus the nuisance's output directions: the other directions carry neither noise nor
    faults and are dropped). Every residual component then has the same noise level, so the norm
    of the residual (:class:`FeatureNorms`) is a chi-distributed statistic under no fault instead
    of a sum dominated by the noisiest sensor's units: a fault seen by a precise sensor (the yaw
    rate, 0.002 rad/s) counts as much as one seen by a noisy one. Blocking is unchanged: the
    nuisance-to-residual transfer is premultiplied by ``W``.

    Parameters
    ----------
    design : FilterDesign
    noise_std : mapping output name -> float
        Measurement-noise standard deviation of every channel of ``design.y_names`` (units of the
        channel).
    rtol : float
        Relative eigenvalue cut-off of ``Sigma``.

    Returns
    -------
    FilterDesign
        Same states, inputs and residual names; ``info["whitening"]`` is ``W`` (q, q) and
        ``info["noise_rank"]`` the rank kept.

    Examples
    --------
    >>> d = FilterDesign(np.zeros((0, 0)), np.zeros((0, 0)), np.zeros((0, 2)), np.zeros((2, 0)),
    ...                  np.zeros((2, 0)), np.eye(2), 0.01, [], ["a", "b"], ["ra", "rb"])
    >>> w = whiten_design(d, {"a": 0.5, "b": 0.01})
    >>> np.diag(w.Dy).round(6).tolist()
    [2.0, 100.0]
    """
    import scipy.linalg as sla

    missing = [y for y in design.y_names if y not in noise_std]
    if missing:
        raise ModelError(f"no noise standard deviation for the measurements {missing}")
    S2 = np.diag([float(noise_std[y]) ** 2 for y in design.y_names])
    X = (sla.solve_discrete_lyapunov(design.A, design.By @ S2 @ design.By.T) if design.order
         else np.zeros((0, 0)))
    sig = design.C @ X @ design.C.T + design.Dy @ S2 @ design.Dy.T
    w, V = np.linalg.eigh(0.5 * (sig + sig.T))
    if not w.size or w.max() <= 0:
        raise ModelError(f"filter {design.residual_names[:1]} has no residual noise to whiten with")
    keep = w > rtol * w.max()
    W = (V[:, keep] / np.sqrt(w[keep])) @ V[:, keep].T
    info = {**design.info, "whitening": W, "noise_rank": int(keep.sum())}
    return FilterDesign(design.A.copy(), design.Bu.copy(), design.By.copy(), W @ design.C, W @ design.Du,
                        W @ design.Dy, design.dt, list(design.u_names), list(design.y_names),
                        list(design.residual_names), info)


def delayed_feedthrough(design: FilterDesign) -> FilterDesign:
    """The same filter with its control feedthrough acting on the previous sample's command.

    A sampled plant under a digital controller measures ``y[k] = C x[k] + D u[k-1]`` (the command
    ``u[k]`` is computed from ``y[k]`` and held over ``[t_k, t_k+1)``; the state update is
    ``x[k+1] = A x[k] + B u[k]``). The filter's ``Du u[k]`` becomes ``Du u[k-1]`` by carrying the
    previous command in ``m`` extra states: ``A' = diag(A, 0)``, ``Bu' = [Bu; I]``,
    ``By' = [By; 0]``, ``C' = [C, Du]``, ``Du' = 0``, ``Dy' = Dy``. Without it the steering
    feed-forward step at a curve entry gives a one-sample spike of ``Du (u[k] - u[k-1])``.

    Examples
    --------
    >>> from fdikit.residuals import FaultDetectionFilter
    >>> d = FilterDesign(np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((0, 1)), np.zeros((1, 0)),
    ...                  np.array([[-2.0]]), np.array([[1.0]]), 0.1, ["u"], ["y"], ["r"])
    >>> dd = delayed_feedthrough(d)
    >>> f = FaultDetectionFilter(dd)
    >>> f.reset(1)
    >>> [float(f.step([u], [0.0])[0, 0]) for u in (1.0, 3.0, 0.0)]   # -2 u[k-1]
    [0.0, -2.0, -6.0]
    """
    nf, m = design.order, len(design.u_names)
    A = np.zeros((nf + m, nf + m))
    A[:nf, :nf] = design.A
    Bu = np.vstack([design.Bu, np.eye(m)])
    By = np.vstack([design.By, np.zeros((m, design.By.shape[1]))])
    C = np.hstack([design.C, design.Du])
    info = {**design.info, "delayed_feedthrough": True}
    return FilterDesign(A, Bu, By, C, np.zeros_like(design.Du), design.Dy.copy(), design.dt,
                        list(design.u_names), list(design.y_names), list(design.residual_names), info)


def band_limited(design: FilterDesign, band_hz: float, order: int = 2) -> FilterDesign:
    """The filter followed by a Butterworth low-pass of ``order`` at ``band_hz`` on every residual.

    The low-pass (discretised by the bilinear transform at the filter's ``dt``) is connected in
    series: state ``[xi; w]``, ``w[k+1] = Al w + Bl r[k]``, ``r'[k] = Cl w + Dl r[k]`` with
    ``r = C xi + Du u + Dy y``. Its DC gain is 1, so a bias fault's residual is unchanged in
    steady state, and the residual's transmission from any nuisance input is the filter's times
    the low-pass's (exactly zero stays exactly zero). ``band_hz <= 0`` returns the design.

    Examples
    --------
    >>> from fdikit.residuals import FaultDetectionFilter
    >>> d = FilterDesign(np.zeros((0, 0)), np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)),
    ...                  np.zeros((1, 0)), np.ones((1, 1)), 0.02, [], ["y"], ["r"])
    >>> f = FaultDetectionFilter(band_limited(d, 1.0))
    >>> f.reset(1)
    >>> r = [float(f.step(np.zeros(0), [1.0])[0, 0]) for _ in range(500)]
    >>> round(r[-1], 9)                                   # unit DC gain
    1.0
    """
    from scipy.signal import butter, tf2ss  # design time only: keeps the runtime import light

    if band_hz <= 0:
        return design
    dt, q = design.dt, len(design.residual_names)
    if not band_hz < 0.5 / dt:
        raise DataError(f"band_hz = {band_hz} Hz must be below the Nyquist frequency {0.5 / dt} Hz")
    b, a = butter(order, band_hz, fs=1.0 / dt)
    al, bl, cl, dl = tf2ss(b, a)
    n1 = al.shape[0]
    Al, Bl, Cl = np.kron(np.eye(q), al), np.kron(np.eye(q), bl), np.kron(np.eye(q), cl)
    Dl = float(dl[0, 0]) * np.eye(q)
    nf = design.order
    A = np.zeros((nf + q * n1, nf + q * n1))
    A[:nf, :nf] = design.A
    A[nf:, :nf] = Bl @ design.C
    A[nf:, nf:] = Al
    Bu = np.vstack([design.Bu, Bl @ design.Du])
    By = np.vstack([design.By, Bl @ design.Dy])
    C = np.hstack([Dl @ design.C, Cl])
    info = {**design.info, "band_hz": float(band_hz), "band_order": int(order)}
    return FilterDesign(A, Bu, By, C, Dl @ design.Du, Dl @ design.Dy, dt, list(design.u_names),
                        list(design.y_names), list(design.residual_names), info)
