"""The implementation form of a discrete linear residual generator: :class:`FilterDesign` (plain
matrices), the model at the filter's sample time, and the stacking of designs into one filter."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.linalg as sla

from ...errors import ModelError
from ...model.linear import LinearFaultModel

__all__ = ["FilterDesign", "stack_designs"]

_EPS = np.finfo(float).eps


@dataclass
class FilterDesign:
    """Implementation form of a discrete linear residual generator (plain matrices).

    ``xi[k+1] = A xi + Bu u + By y``, ``r = C xi + Du u + Dy y``.

    Attributes
    ----------
    A : ndarray (nf, nf)
    Bu : ndarray (nf, m)
        Gain on the controls ``u`` (channels ``u_names``).
    By : ndarray (nf, p)
        Gain on the measurements ``y`` (channels ``y_names``).
    C : ndarray (q, nf)
    Du : ndarray (q, m)
    Dy : ndarray (q, p)
    dt : float
        Sample time (s).
    u_names, y_names : list of str
    residual_names : list of str
        ``q`` residual channel names.
    info : dict
        Method, target and nuisance, conditions checked with their ranks, ``gamma``, filter
        eigenvalues, reduction order (see the design functions).
    internal : LinearFaultModel or None
        Internal form against the design model (:func:`internal_form`), set by the design
        functions: the transfer from every input group of the model to the residual.
    """

    A: np.ndarray
    Bu: np.ndarray
    By: np.ndarray
    C: np.ndarray
    Du: np.ndarray
    Dy: np.ndarray
    dt: float
    u_names: list[str]
    y_names: list[str]
    residual_names: list[str]
    info: dict[str, Any] = field(default_factory=dict)
    internal: LinearFaultModel | None = field(default=None, repr=False)

    @property
    def order(self) -> int:
        """Number of filter states ``nf``."""
        return self.A.shape[0]

    def to_dict(self, *, inline: int = 100) -> dict[str, Any]:
        """Matrices and names (``info`` omitted) as plain data.

        A matrix with at most ``inline`` entries is a nested list (readable and editable in an
        artifact's JSON manifest); a larger one stays a float array (stored exactly in the
        artifact's NPZ; a 60-state filter bank's JSON was 1.7 MB of decimal text). Pass
        ``inline=None`` for lists throughout (JSON-ready).
        """
        def conv(a: np.ndarray):
            return a.tolist() if inline is None or a.size <= inline else np.array(a, float)

        out: dict[str, Any] = {k: conv(getattr(self, k)) for k in ("A", "Bu", "By", "C", "Du", "Dy")}
        out.update(dt=self.dt, u_names=self.u_names, y_names=self.y_names,
                   residual_names=self.residual_names)
        return out

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> FilterDesign:
        """Inverse of :meth:`to_dict`."""
        mats = {k: np.asarray(d[k], float) for k in ("A", "Bu", "By", "C", "Du", "Dy")}
        nf, q = len(d["A"]), len(d["residual_names"])
        m, p = len(d["u_names"]), len(d["y_names"])
        for k, shp in {"A": (nf, nf), "Bu": (nf, m), "By": (nf, p), "C": (q, nf), "Du": (q, m),
                       "Dy": (q, p)}.items():
            mats[k] = mats[k].reshape(shp)
        return cls(**mats, dt=float(d["dt"]), u_names=list(d["u_names"]), y_names=list(d["y_names"]),
                   residual_names=list(d["residual_names"]))


def _discrete(model: LinearFaultModel, dt: float | None) -> LinearFaultModel:
    if not isinstance(model, LinearFaultModel):
        raise ModelError(f"a LinearFaultModel is needed, got {type(model).__name__}")
    if model.is_discrete:
        if dt is not None and abs(dt - model.dt) > 1e-12 * max(1.0, model.dt):
            raise ModelError(f"model is discrete with dt = {model.dt}, cannot design for dt = {dt}")
        return model
    if dt is None:
        raise ModelError("a continuous model needs the sample time dt of the filter")
    return model.discretize(dt)


def stack_designs(designs: Sequence[FilterDesign]) -> FilterDesign:
    """Fuse several filters reading the same channels into one block-diagonal filter.

    The fused filter's residuals are the concatenation of the members' (in order); its inputs
    are the union of their ``u`` and ``y`` channels (first appearance order). Running one fused
    filter costs a few matrix products per sample instead of a few per member.

    Examples
    --------
    >>> import numpy as np
    >>> a = FilterDesign(np.array([[0.5]]), np.zeros((1, 0)), np.array([[1.0]]), np.array([[1.0]]),
    ...                  np.zeros((1, 0)), np.zeros((1, 1)), 0.1, [], ["y1"], ["ra"])
    >>> b = FilterDesign(np.array([[0.2]]), np.zeros((1, 0)), np.array([[1.0]]), np.array([[2.0]]),
    ...                  np.zeros((1, 0)), np.zeros((1, 1)), 0.1, [], ["y2"], ["rb"])
    >>> s = stack_designs([a, b])
    >>> s.y_names, s.residual_names, s.By.tolist()
    (['y1', 'y2'], ['ra', 'rb'], [[1.0, 0.0], [0.0, 1.0]])
    """
    designs = list(designs)
    if not designs:
        raise ModelError("stack_designs needs at least one design")
    dt = designs[0].dt
    for d in designs:
        if abs(d.dt - dt) > 1e-12 * dt:
            raise ModelError(f"designs have different sample times: {dt} and {d.dt}")
    u_names = list(dict.fromkeys(s for d in designs for s in d.u_names))
    y_names = list(dict.fromkeys(s for d in designs for s in d.y_names))
    res = [s for d in designs for s in d.residual_names]
    if len(set(res)) != len(res):
        raise ModelError(f"residual names collide: {res}")
    nf, q = sum(d.order for d in designs), len(res)
    A = sla.block_diag(*[d.A for d in designs]) if nf else np.zeros((0, 0))
    Bu, By = np.zeros((nf, len(u_names))), np.zeros((nf, len(y_names)))
    C, Du, Dy = np.zeros((q, nf)), np.zeros((q, len(u_names))), np.zeros((q, len(y_names)))
    i = j = 0
    for d in designs:
        iu = [u_names.index(s) for s in d.u_names]
        iy = [y_names.index(s) for s in d.y_names]
        rows, outs = slice(i, i + d.order), slice(j, j + len(d.residual_names))
        Bu[rows, iu], By[rows, iy] = d.Bu, d.By
        C[outs, rows] = d.C
        Du[outs, iu], Dy[outs, iy] = d.Du, d.Dy
        i, j = i + d.order, j + len(d.residual_names)
    return FilterDesign(A, Bu, By, C, Du, Dy, dt, u_names, y_names, res,
                        info={"method": "stack", "members": [d.residual_names for d in designs]})
