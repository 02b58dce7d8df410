"""Observer-based output residuals for linear models (Luenberger or steady-state Kalman gain).

The residual generator of a discrete model ``x[k+1] = A x + B u``, ``y = C x + D u`` is the
predictor-form observer

    r[k]      = y[k] - C xh[k] - D u[k]
    xh[k+1]   = A xh[k] + B u[k] + L r[k]

whose estimation error ``e = x - xh`` obeys ``e[k+1] = (A - L C) e + (B_g - L D_g) v_g`` for every
non-control input group g (disturbances, faults, noise): the controls cancel exactly, the faults
reach the residual through ``C (zI - A + LC)^-1 (B_f - L D_f) + D_f``.

Design (:func:`design_observer_residual`) returns plain matrices (:class:`ObserverDesign`); the
runtime (:class:`ObserverResidual`) only multiplies. :meth:`ObserverDesign.as_filter` gives the
generic filter form, so :func:`fdikit.residuals.internal_form` recomputes the transfer from every
input group of a model to the residual by composing plant and observer.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.linalg as sla
from scipy.signal import place_poles

from ..errors import ConditionError, ModelError
from ..model.linear import LinearFaultModel
from .fdf import FaultDetectionFilter, FilterDesign, _discrete

__all__ = ["ObserverDesign", "ObserverResidual", "design_observer_residual"]


@dataclass
class ObserverDesign:
    """Gains and matrices of a discrete observer residual generator (see module docstring).

    Attributes
    ----------
    A, B, C, D : ndarray
        Discrete model used by the observer (controls only), shapes (n,n), (n,m), (p,n), (p,m).
    L : ndarray (n, p)
        Observer gain.
    dt : float
        Sample time (s).
    u_names, y_names : list of str
        Control and measurement channel names the runtime reads.
    residual_names : list of str
        One residual per measurement, ``"r:<output>"``.
    info : dict
        Method, closed-loop eigenvalues and spectral radius, detectability verdict.
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    L: np.ndarray
    dt: float
    u_names: list[str]
    y_names: list[str]
    residual_names: list[str]
    info: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """Matrices and names as plain data (``info`` is summarised)."""
        out: dict[str, Any] = {k: getattr(self, k).tolist() for k in ("A", "B", "C", "D", "L")}
        out.update(dt=self.dt, u_names=list(self.u_names), y_names=list(self.y_names),
                   residual_names=list(self.residual_names),
                   info={"method": self.info.get("method"),
                         "spectral_radius": float(self.info.get("spectral_radius", np.nan))})
        return out

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> ObserverDesign:
        n, p = len(d["A"]), len(d["y_names"])
        m = len(d["u_names"])
        mats = {k: np.asarray(d[k], float).reshape(shape) for k, shape in
                (("A", (n, n)), ("B", (n, m)), ("C", (p, n)), ("D", (p, m)), ("L", (n, p)))}
        return cls(**mats, dt=float(d["dt"]), u_names=list(d["u_names"]), y_names=list(d["y_names"]),
                   residual_names=list(d["residual_names"]), info=dict(d.get("info", {})))

    def as_filter(self) -> FilterDesign:
        """The same generator in the generic filter form ``xi+ = Af xi + Bu u + By y``,
        ``r = Cf xi + Du u + Dy y``: Af = A - L C, Bu = B - L D, By = L, Cf = -C, Du = -D, Dy = I."""
        p = self.C.shape[0]
        return FilterDesign(
            A=self.A - self.L @ self.C, Bu=self.B - self.L @ self.D, By=self.L.copy(), C=-self.C,
            Du=-self.D, Dy=np.eye(p), dt=self.dt, u_names=list(self.u_names), y_names=list(self.y_names),
            residual_names=list(self.residual_names), info=dict(self.info),
        )


def design_observer_residual(
    model: LinearFaultModel,
    *,
    dt: float | None = None,
    method: str = "kalman",
    Q: Any = None,
    R: Any = None,
    poles: Any = None,
) -> ObserverDesign:
    """Design an observer-based output residual generator for a linear model.

    Parameters
    ----------
    model : LinearFaultModel
        Continuous (then ``dt`` is required and the model is discretised by ZOH) or discrete.
    dt : float, optional
        Sample time of the residual generator (s).
    method : {"kalman", "poles"}
        ``"kalman"``: the steady-state (predictor) Kalman gain from the discrete Riccati equation
        with process noise covariance ``Q`` (n x n, default ``B_w B_w'`` plus 1e-6 I) and
        measurement covariance ``R`` (p x p, default ``D_w D_w'`` plus 1e-6 I, or I when the model
        has no noise group). ``"poles"``: ``A - L C`` gets the discrete ``poles`` (scipy
        ``place_poles``).

    Returns
    -------
    ObserverDesign

    Raises
    ------
    ConditionError
        ``detectability`` when (A, C) has an unobservable mode on or outside the unit circle, or
        ``stability`` when the designed ``A - L C`` is not Schur stable.

    Examples
    --------
    >>> from fdikit.model import LinearFaultModel
    >>> m = LinearFaultModel([[0.9]], [[1.0]], [[1.0]], dt=0.1, inputs=["u"], outputs=["y"])
    >>> d = design_observer_residual(m, method="poles", poles=[0.5])
    >>> round(float(d.L[0, 0]), 6)
    0.4
    """
    md = _discrete(model, dt)
    A, C = md.A, md.C
    n, p = A.shape[0], C.shape[0]
    # detectability by the PBH test: every mode with |z| >= 1 must be observable
    ev = np.linalg.eigvals(A)
    for z in ev:
        if abs(z) >= 1 - 1e-9:
            s = np.linalg.svd(np.vstack([A - z * np.eye(n), C.astype(complex)]), compute_uv=False)
            if s[-1] <= 1e-9 * max(1.0, s[0]):
                raise ConditionError(
                    "detectability",
                    f"(A, C) has an unobservable mode z = {z:.6g} with |z| = {abs(z):.6g} >= 1",
                    {"mode": complex(z), "pbh_min_singular_value": float(s[-1])},
                )
    if method == "kalman":
        Bw, Dw = md.B_of("w"), md.D_of("w")
        Qm = Bw @ Bw.T + 1e-6 * np.eye(n) if Q is None else np.atleast_2d(np.asarray(Q, float))
        if R is None:
            Rm = Dw @ Dw.T + 1e-6 * np.eye(p) if Dw.size and np.any(Dw) else np.eye(p)
        else:
            Rm = np.atleast_2d(np.asarray(R, float))
        if Qm.shape != (n, n) or Rm.shape != (p, p):
            raise ModelError(f"Q must be {(n, n)} and R {(p, p)}, got {Qm.shape} and {Rm.shape}")
        P = sla.solve_discrete_are(A.T, C.T, Qm, Rm)
        L = A @ P @ C.T @ np.linalg.inv(C @ P @ C.T + Rm)
    elif method == "poles":
        if poles is None:
            raise ModelError("method='poles' needs the discrete poles of A - L C")
        poles = np.asarray(poles)
        if poles.size != n:
            raise ModelError(f"need {n} poles, got {poles.size}")
        L = place_poles(A.T, C.T, poles).gain_matrix.T
    else:
        raise ModelError(f"unknown method {method!r}; use 'kalman' or 'poles'")
    eig = np.linalg.eigvals(A - L @ C)
    rho = float(np.max(np.abs(eig))) if n else 0.0
    if rho >= 1:
        raise ConditionError("stability", f"observer A - L C has spectral radius {rho:.6g} >= 1",
                             {"eigenvalues": eig.tolist()})
    return ObserverDesign(
        A=A.copy(), B=md.B.copy(), C=C.copy(), D=md.D.copy(), L=np.asarray(L, float), dt=float(md.dt),
        u_names=list(md.inputs), y_names=list(md.outputs),
        residual_names=[f"r:{y}" for y in md.outputs],
        info={"method": method, "eigenvalues": eig, "spectral_radius": rho, "detectable": True},
    )


class ObserverResidual(FaultDetectionFilter):
    """Runtime of an :class:`ObserverDesign`: its filter form (:meth:`ObserverDesign.as_filter`)
    run by the compiled :class:`~fdikit.residuals.FaultDetectionFilter` (batch ``run`` and
    streaming ``reset``/``step``, bitwise equal). The filter state is the estimate ``xh``.

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit.model import LinearFaultModel
    >>> m = LinearFaultModel([[0.9]], [[1.0]], [[1.0]], dt=0.1, inputs=["u"], outputs=["y"])
    >>> gen = ObserverResidual(design_observer_residual(m, method="poles", poles=[0.5]))
    >>> gen.reset(1)
    >>> gen.step([1.0], [0.0]).tolist()   # y differs from the prediction C xh = 0 by 0
    [[0.0]]
    """

    def __init__(self, design: ObserverDesign, x0: Any = None):
        super().__init__(design.as_filter(), x0)
        self.observer_design = design
