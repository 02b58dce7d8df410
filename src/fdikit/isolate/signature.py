"""Isolation by a fault signature matrix (structured residuals).

A residual bank (:func:`fdikit.residuals.bank.design_residual_bank`) or a hand-made table gives, for
every fault, the residuals it makes fire: the fault signature matrix ``S`` (faults x residuals, 0/1).
:class:`SignatureIsolator` reads the alarm pattern of the residuals and returns the fault(s) whose
signature explains it: exact column matching when the pattern is a signature, else the nearest
signatures -- maximum likelihood with detection probability ``pd`` where ``S = 1`` and false-alarm
probability ``pf`` where ``S = 0`` (with ``pd = 1 - pf`` this is the smallest Hamming distance) -- and
always the ambiguity set (all faults that tie). The no-alarm pattern is the nominal class.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ..base.stage import ResidualProcessor
from ..errors import DataError, ModelError
from .decide import Diagnosis
from .dmatrix import DMatrix

__all__ = ["SignatureDecision", "SignatureIsolator"]


class SignatureIsolator:
    """Diagnose faults from residual alarms with a fault signature matrix.

    Parameters
    ----------
    signature : array_like (n_f, n_r) of 0/1, or a signature object
        The matrix, or an object with ``matrix``, ``faults`` and ``residuals`` (e.g. the
        ``signature`` of a residual bank; its ``useful`` entries are used with ``use="useful"``).
    faults : sequence of str, optional
        Row names (taken from the signature object when it has them).
    residuals : sequence of str, optional
        Column names.
    nominal : str or None
        Name of the no-fault class (an all-zero row added as the first candidate); ``None``: none.
    pd, pf : float or array_like (n_r,)
        Probability that a residual alarms where the signature is 1 (``pd``) and where it is 0 (``pf``);
        the defaults 0.99 / 0.01 make the diagnosis the nearest signature in Hamming distance.
    use : {"matrix", "useful"}
        For a bank's signature: the structural 0/1 matrix, or only the entries that passed the
        sensitivity check (a weak entry is then expected not to alarm).

    Examples
    --------
    >>> S = [[0, 1, 1], [1, 0, 1], [1, 1, 0]]
    >>> iso = SignatureIsolator(S, ["V", "i", "w"], ["r1", "r2", "r3"])
    >>> d = iso.diagnose([[0, 1, 1], [0, 0, 0], [1, 1, 1], [0, 0, 1]])
    >>> d.best, d.ambiguity
    (['V', 'F0', 'V', 'F0'], [('V',), ('F0',), ('V', 'i', 'w'), ('F0', 'V', 'i')])
    """

    def __init__(self, signature: Any, faults: Sequence[str] | None = None,
                 residuals: Sequence[str] | None = None, *, nominal: str | None = "F0",
                 pd: Any = 0.99, pf: Any = 0.01, use: str = "matrix"):
        if use not in ("matrix", "useful"):
            raise ModelError(f"use must be 'matrix' or 'useful', got {use!r}")
        if hasattr(signature, "matrix"):
            M = np.asarray(signature.matrix)
            if use == "useful":
                M = M.astype(bool) & np.asarray(signature.useful, bool)
            faults = list(signature.faults) if faults is None else faults
            residuals = list(signature.residuals) if residuals is None else residuals
        else:
            if use == "useful":
                raise ModelError("use='useful' needs a signature object with a 'useful' matrix")
            M = np.asarray(signature)
        if M.ndim != 2:
            raise ModelError(f"a signature matrix is 2-D (faults x residuals), got shape {M.shape}")
        faults = [f"f{i}" for i in range(M.shape[0])] if faults is None else [str(f) for f in faults]
        residuals = [f"r{j}" for j in range(M.shape[1])] if residuals is None else [str(r) for r in residuals]
        if nominal is not None:
            if nominal in faults:
                raise ModelError(f"the nominal class {nominal!r} is also a fault name")
            M = np.vstack([np.zeros((1, M.shape[1]), M.dtype), M])
            faults = [nominal, *faults]
        pd_a = np.broadcast_to(np.asarray(pd, float), (M.shape[1],))
        pf_a = np.broadcast_to(np.asarray(pf, float), (M.shape[1],))
        self.dmatrix = DMatrix(faults, residuals, M, pd=pd_a, pf=pf_a)
        self.faults, self.residuals, self.nominal = faults, residuals, nominal

    @property
    def matrix(self) -> np.ndarray:
        """The signature matrix used (nominal row first when there is one), 0/1 int."""
        return self.dmatrix.d.astype(int)

    def ambiguity_groups(self) -> list[tuple[str, ...]]:
        """Faults with equal signatures: no alarm pattern tells them apart."""
        return self.dmatrix.ambiguity_groups()

    def diagnose(self, alarms: Any) -> Diagnosis:
        """Diagnoses of alarm patterns.

        Parameters
        ----------
        alarms : array_like of bool (runs, n_r) or (n_r,), mapping residual -> bool / (runs,), or
            Signals whose channels include the residual names (every sample a pattern, run 0).

        Returns
        -------
        fdikit.isolate.decide.Diagnosis
            ``best``, ``ambiguity`` (all faults that tie), ``posterior``.
        """
        if hasattr(alarms, "values") and hasattr(alarms, "index") and hasattr(alarms, "names"):
            missing = [r for r in self.residuals if r not in alarms.names]
            if missing:
                raise DataError(f"the alarm signals lack residual channels {missing} (have {alarms.names})")
            alarms = alarms.values[0][:, alarms.index(self.residuals)] != 0
        if isinstance(alarms, Mapping):
            return self.dmatrix.diagnose(alarms)
        a = np.asarray(alarms)
        if a.ndim == 1:
            a = a[None]
        if a.ndim != 2 or a.shape[1] != len(self.residuals):
            raise DataError(f"alarms have shape {np.shape(alarms)}; expected (runs, {len(self.residuals)}) "
                            f"for residuals {self.residuals}")
        return self.dmatrix.diagnose(a != 0)

    def __repr__(self) -> str:
        return f"SignatureIsolator(faults={self.faults}, residuals={self.residuals})"


class SignatureDecision(ResidualProcessor):
    """Streaming isolation by a fault signature matrix: residual alarms in, one channel per fault out.

    At every sample the alarm pattern (``alarm > 0.5`` per residual) is compared with every fault's
    signature and with the all-zero nominal pattern; the faults at the smallest Hamming distance
    form the ambiguity set. Output ``fault:<name>`` is ``1 / m`` for each of the ``m`` faults of
    that set (``1`` when the fault is isolated), 0 otherwise, and all zero when the nominal pattern
    is among the nearest. A :class:`~fdikit.monitor.Decision` at a level above 0.5 then announces
    isolated faults only.

    Parameters
    ----------
    signature : array_like (n_f, n_r) of 0/1, or a signature object (``matrix``, ``faults``)
    faults : sequence of str, optional
        Fault names (from the signature object when it has them).
    inputs : sequence of str
        The alarm channels, one per signature column, in order.

    Examples
    --------
    >>> d = SignatureDecision([[0, 1, 1], [1, 0, 1], [1, 1, 0]], ["V", "i", "w"], ["a1", "a2", "a3"])
    >>> d.reset(1)
    >>> d.step([0.0, 1.0, 1.0]).tolist(), d.step([1.0, 1.0, 1.0]).round(3).tolist()
    ([[1.0, 0.0, 0.0]], [[0.333, 0.333, 0.333]])
    """

    _state_attrs = ()

    def __init__(self, signature: Any, faults: Sequence[str] | None = None,
                 inputs: Sequence[str] | None = None):
        M = np.asarray(getattr(signature, "matrix", signature))
        faults = list(getattr(signature, "faults", None) or []) if faults is None else list(faults)
        if M.ndim != 2 or not np.isin(M, (0, 1)).all():
            raise ModelError(f"a signature matrix is 2-D of 0/1 (faults x residuals), got {M.tolist()}")
        if len(faults) != M.shape[0]:
            raise ModelError(f"{len(faults)} fault names for a signature with {M.shape[0]} rows")
        if inputs is None or len(list(inputs)) != M.shape[1]:
            raise ModelError(f"give one alarm channel per signature column ({M.shape[1]}), got {inputs}")
        self.signature = M.astype(np.int8)
        self.faults = [str(f) for f in faults]
        self.input_names = [str(s) for s in inputs]
        self.output_names = [f"fault:{f}" for f in self.faults]
        self._rows = np.vstack([np.zeros((1, M.shape[1]), np.int8), self.signature])
        self.reset(1)

    def to_dict(self) -> dict:
        return {"signature": self.signature.tolist(), "faults": self.faults, "inputs": self.input_names}

    @classmethod
    def from_dict(cls, d: Mapping) -> SignatureDecision:
        return cls(d["signature"], d["faults"], d["inputs"])

    def reset(self, runs: int = 1) -> None:
        self._runs = int(runs)

    def _decide(self, a: np.ndarray) -> np.ndarray:
        """a (..., n_r) alarm values -> (..., n_f) ambiguity weights."""
        if not np.all(np.isfinite(a)):
            idx = np.argwhere(~np.isfinite(a))[0]
            raise DataError(f"alarm channel {self.input_names[idx[-1]]!r} is not finite (sample index "
                            f"{tuple(int(i) for i in idx[:-1])})")
        bits = (a > 0.5).astype(np.int8)
        dist = np.abs(bits[..., None, :] - self._rows).sum(axis=-1)          # (..., 1 + n_f)
        near = dist == dist.min(axis=-1, keepdims=True)
        w = near[..., 1:].astype(float)
        w[near[..., 0]] = 0.0
        m = w.sum(axis=-1, keepdims=True)
        return np.divide(w, m, out=np.zeros_like(w), where=m > 0)

    def _step(self, r: np.ndarray) -> np.ndarray:
        return self._decide(r)

    def run(self, signals: Any) -> Any:
        from ..signals import Signals

        r = signals.values[:, :, signals.index(self.input_names)]
        self.reset(signals.runs)
        return Signals(signals.t, self._decide(r), self.output_names, check=False)
