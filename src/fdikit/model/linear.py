"""Linear state-space models with named signals and typed input groups.

A :class:`LinearFaultModel` is

    x' = A x + B_u u + B_d d + B_f f + B_w w        (continuous, ``dt is None``)
    x[k+1] = A x[k] + ...                            (discrete, sample time ``dt``)
    y  = C x + D_u u + D_d d + D_f f + D_w w

with four input groups: controls ``u``, disturbances ``d``, faults ``f`` and noise ``w``. Every
state, input and output has a name. Faults are declared by name:

* ``"actuator:<input>"``: an additive fault on control input ``<input>`` (direction = that
  column of B_u and D_u);
* ``"sensor:<output>"``: an additive fault on output ``<output>`` (B_f column 0, D_f column e_j);
* any other name with an explicit direction ``(b, d)`` in state and output space.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import ModelError

__all__ = ["GROUPS", "InputGroup", "LinearFaultModel"]

#: The input groups, in the order they are stacked in ``B`` and ``D``.
GROUPS = ("u", "d", "f", "w")
_GROUP_NAMES = {"u": "controls", "d": "disturbances", "f": "faults", "w": "noise"}


def _mat(M: Any, shape: tuple[int, int], what: str) -> np.ndarray:
    if M is None:
        return np.zeros(shape)
    M = np.asarray(M, dtype=float)
    if M.ndim == 1 and shape[1] == 1 and M.size == shape[0]:
        M = M.reshape(-1, 1)  # one column given as a 1-D array
    M = np.atleast_2d(M)
    if M.shape != shape:
        raise ModelError(f"{what} must have shape {shape}, got {M.shape}")
    if not np.all(np.isfinite(M)):
        raise ModelError(f"{what} contains NaN or inf")
    return M


def _ncols(Bm: Any, Dm: Any, n: int, p: int) -> int:
    """Number of columns of a group given by its B (n rows) and/or D (p rows) matrix."""
    if Bm is not None:
        return _as_columns(Bm, n, "B").shape[1]
    if Dm is not None:
        return _as_columns(Dm, p, "D").shape[1]
    return 0


def _as_columns(M: Any, rows: int, what: str) -> np.ndarray:
    """``M`` as a matrix of ``rows`` rows (a 1-D array of ``rows`` entries is one column), or a
    ModelError naming it (never numpy's "cannot reshape")."""
    M = np.asarray(M, dtype=float)
    if M.ndim == 1:
        if M.size != rows:
            raise ModelError(f"{what} given as a 1-D array of {M.size} entries: a single column needs "
                             f"{rows} (one per {'state' if what.startswith('B') else 'output'}); "
                             f"give a ({rows}, k) matrix for k columns")
        return M.reshape(rows, 1)
    if M.ndim != 2 or M.shape[0] != rows:
        raise ModelError(f"{what} must have {rows} rows, got shape {M.shape}")
    return M


def _names(names: Sequence[str] | None, n: int, prefix: str, what: str) -> list[str]:
    if names is None:
        return [f"{prefix}{i}" for i in range(n)]
    names = [str(s) for s in names]
    if len(names) != n:
        raise ModelError(f"{len(names)} {what} names given for {n} {what}s: {names}")
    if len(set(names)) != n:
        dup = sorted({s for s in names if names.count(s) > 1})
        raise ModelError(f"duplicated {what} names: {dup}")
    return names


@dataclass(frozen=True)
class InputGroup:
    """Columns of B and D that belong to one input group, with their names."""

    names: tuple[str, ...]
    B: np.ndarray  # (n, m)
    D: np.ndarray  # (p, m)

    @property
    def size(self) -> int:
        return len(self.names)


class LinearFaultModel:
    """Linear state-space model with named states, inputs, outputs and typed input groups.

    Parameters
    ----------
    A : array_like (n, n)
    B : array_like (n, m_u)
        Control input matrix.
    C : array_like (p, n)
    D : array_like (p, m_u), optional
        Control feedthrough (zeros by default).
    dt : float or None
        Sample time in seconds for a discrete model; ``None`` for continuous time.
    states, inputs, outputs : sequence of str, optional
        Names (defaults ``x0..``, ``u0..``, ``y0..``).
    Bd, Dd, disturbances : optional
        Disturbance matrices and names.
    Bw, Dw, noises : optional
        Noise matrices and names.
    faults : iterable, optional
        Fault declarations: ``"actuator:<input>"``, ``"sensor:<output>"`` or
        ``(name, b, d)`` with ``b`` of length n and ``d`` of length p (``d`` may be ``None``).
    name : str
        Model name used in reprs and error messages.

    Examples
    --------
    >>> from fdikit.model import LinearFaultModel
    >>> m = LinearFaultModel([[-1.0]], [[1.0]], [[1.0]], states=["v"], inputs=["thr"],
    ...                      outputs=["v_meas"], faults=["actuator:thr", "sensor:v_meas"])
    >>> m.fault_names
    ['actuator:thr', 'sensor:v_meas']
    >>> m.B_of("f").ravel().tolist(), m.D_of("f").ravel().tolist()
    ([1.0, 0.0], [0.0, 1.0])
    """

    def __init__(
        self,
        A: Any,
        B: Any,
        C: Any,
        D: Any = None,
        *,
        dt: float | None = None,
        states: Sequence[str] | None = None,
        inputs: Sequence[str] | None = None,
        outputs: Sequence[str] | None = None,
        Bd: Any = None,
        Dd: Any = None,
        disturbances: Sequence[str] | None = None,
        Bw: Any = None,
        Dw: Any = None,
        noises: Sequence[str] | None = None,
        faults: Iterable[Any] = (),
        name: str = "",
    ):
        A = np.atleast_2d(np.asarray(A, dtype=float))
        if A.ndim != 2 or A.shape[0] != A.shape[1]:
            raise ModelError(f"A must be square, got shape {A.shape}")
        n = A.shape[0]
        C = np.atleast_2d(np.asarray(C, dtype=float))
        if C.shape[1] != n:
            raise ModelError(f"C must have {n} columns (one per state), got shape {C.shape}")
        p = C.shape[0]
        B = _as_columns(B, n, "B") if B is not None else np.zeros((n, 0))
        mu = B.shape[1]
        if dt is not None and not (float(dt) > 0):
            raise ModelError(f"dt must be a positive sample time or None, got {dt}")
        self.A = _mat(A, (n, n), "A")
        self.C = _mat(C, (p, n), "C")
        self.dt = None if dt is None else float(dt)
        self.name = str(name)
        self.states = _names(states, n, "x", "state")
        self.outputs = _names(outputs, p, "y", "output")
        self._groups: dict[str, InputGroup] = {}
        self._set_group("u", _names(inputs, mu, "u", "input"), _mat(B, (n, mu), "B"),
                        _mat(D, (p, mu), "D"))
        nd = _ncols(Bd, Dd, n, p)
        self._set_group("d", _names(disturbances, nd, "d", "disturbance"),
                        _mat(Bd, (n, nd), "Bd"), _mat(Dd, (p, nd), "Dd"))
        nw = _ncols(Bw, Dw, n, p)
        self._set_group("w", _names(noises, nw, "w", "noise"),
                        _mat(Bw, (n, nw), "Bw"), _mat(Dw, (p, nw), "Dw"))
        self._set_group("f", [], np.zeros((n, 0)), np.zeros((p, 0)))
        for spec in faults:
            self._add_fault_inplace(spec)

    # ------------------------------------------------------------------ groups
    def _set_group(self, g: str, names: list[str], B: np.ndarray, D: np.ndarray) -> None:
        self._groups[g] = InputGroup(tuple(names), B, D)
        all_names = [s for k in GROUPS if k in self._groups for s in self._groups[k].names]
        if len(set(all_names)) != len(all_names):
            dup = sorted({s for s in all_names if all_names.count(s) > 1})
            raise ModelError(f"input names must be unique across groups; duplicated: {dup}")

    def _add_fault_inplace(self, spec: Any) -> None:
        n, p = self.n_states, self.n_outputs
        if isinstance(spec, str):
            kind, _, target = spec.partition(":")
            if kind == "actuator":
                j = self._lookup(self.input_names("u"), target, "control input")
                b, d = self.B_of("u")[:, j], self.D_of("u")[:, j]
            elif kind == "sensor":
                j = self._lookup(self.outputs, target, "output")
                b, d = np.zeros(n), np.eye(p)[:, j]
            else:
                raise ModelError(
                    f"fault {spec!r}: a fault declared by name alone must be "
                    "'actuator:<input>' or 'sensor:<output>'; give (name, b, d) for others"
                )
            fname = spec
        else:
            try:
                fname, b, d = spec
            except (TypeError, ValueError):
                raise ModelError(f"fault declaration {spec!r} must be a str or (name, b, d)") from None
            fname = str(fname)
            b = np.zeros(n) if b is None else np.asarray(b, dtype=float).reshape(-1)
            d = np.zeros(p) if d is None else np.asarray(d, dtype=float).reshape(-1)
            if b.size != n or d.size != p:
                raise ModelError(f"fault {fname!r}: direction b needs {n} entries and d {p}, "
                                 f"got {b.size} and {d.size}")
            for key, v in (("b", b), ("d", d)):
                if not np.all(np.isfinite(v)):
                    raise ModelError(f"fault {fname!r}: direction {key} contains a non-finite value at "
                                     f"entry {int(np.flatnonzero(~np.isfinite(v))[0])}: {v.tolist()}")
        g = self._groups["f"]
        self._set_group("f", [*g.names, fname], np.column_stack([g.B, b]) if g.size else b[:, None],
                        np.column_stack([g.D, d]) if g.size else d[:, None])

    @staticmethod
    def _lookup(names: Sequence[str], target: str, what: str) -> int:
        try:
            return list(names).index(target)
        except ValueError:
            raise ModelError(f"unknown {what} {target!r}; known: {list(names)}") from None

    def copy(self) -> LinearFaultModel:
        new = object.__new__(LinearFaultModel)
        new.A, new.C, new.dt, new.name = self.A.copy(), self.C.copy(), self.dt, self.name
        new.states, new.outputs = list(self.states), list(self.outputs)
        new._groups = {k: InputGroup(g.names, g.B.copy(), g.D.copy()) for k, g in self._groups.items()}
        return new

    def with_faults(self, *specs: Any) -> LinearFaultModel:
        """A copy with more faults declared (see the class docstring for the forms)."""
        new = self.copy()
        for s in specs:
            new._add_fault_inplace(s)
        return new

    def without_faults(self) -> LinearFaultModel:
        new = self.copy()
        new._groups["f"] = InputGroup((), np.zeros((self.n_states, 0)), np.zeros((self.n_outputs, 0)))
        return new

    # ------------------------------------------------------------------ accessors
    @property
    def n_states(self) -> int:
        return self.A.shape[0]

    @property
    def n_outputs(self) -> int:
        return self.C.shape[0]

    @property
    def is_discrete(self) -> bool:
        return self.dt is not None

    def input_names(self, group: str | None = None) -> list[str]:
        """Names of one group's inputs, or of all inputs in the order u, d, f, w."""
        if group is None:
            return [s for g in GROUPS for s in self._groups[g].names]
        return list(self._group(group).names)

    @property
    def inputs(self) -> list[str]:
        """Names of the control inputs (group ``u``)."""
        return self.input_names("u")

    @property
    def fault_names(self) -> list[str]:
        return self.input_names("f")

    def _group(self, g: str) -> InputGroup:
        if g not in self._groups:
            raise ModelError(f"unknown input group {g!r}; groups are {GROUPS}")
        return self._groups[g]

    def B_of(self, group: str) -> np.ndarray:
        """Input matrix of one group (``"u"``, ``"d"``, ``"f"`` or ``"w"``)."""
        return self._group(group).B

    def D_of(self, group: str) -> np.ndarray:
        """Feedthrough matrix of one group."""
        return self._group(group).D

    @property
    def B(self) -> np.ndarray:
        """Control input matrix B_u."""
        return self.B_of("u")

    @property
    def D(self) -> np.ndarray:
        """Control feedthrough D_u."""
        return self.D_of("u")

    @property
    def B_all(self) -> np.ndarray:
        """All input matrices stacked ``[B_u B_d B_f B_w]``."""
        return np.hstack([self._groups[g].B for g in GROUPS])

    @property
    def D_all(self) -> np.ndarray:
        return np.hstack([self._groups[g].D for g in GROUPS])

    def group_slices(self) -> dict[str, slice]:
        """Column slices of each group inside ``B_all`` / ``D_all``."""
        out, k = {}, 0
        for g in GROUPS:
            m = self._groups[g].size
            out[g] = slice(k, k + m)
            k += m
        return out

    def fault_direction(self, fault: str) -> tuple[np.ndarray, np.ndarray]:
        """State direction ``b`` and output direction ``d`` of a declared fault."""
        j = self._lookup(self.fault_names, fault, "fault")
        return self.B_of("f")[:, j].copy(), self.D_of("f")[:, j].copy()

    def state_index(self, names: str | Iterable[str]) -> list[int]:
        names = [names] if isinstance(names, str) else list(names)
        return [self._lookup(self.states, s, "state") for s in names]

    def output_index(self, names: str | Iterable[str]) -> list[int]:
        names = [names] if isinstance(names, str) else list(names)
        return [self._lookup(self.outputs, s, "output") for s in names]

    # ------------------------------------------------------------------ transformations
    def with_matrices(
        self,
        A: np.ndarray,
        C: np.ndarray,
        groups: Mapping[str, tuple[np.ndarray, np.ndarray]],
        *,
        states: Sequence[str] | None = None,
        outputs: Sequence[str] | None = None,
        dt: float | str | None = "same",
    ) -> LinearFaultModel:
        """A model with the same input names and new matrices (used by reduction and transforms)."""
        new = object.__new__(LinearFaultModel)
        n, p = A.shape[0], C.shape[0]
        new.A, new.C = np.array(A, float), np.array(C, float)
        new.dt = self.dt if dt == "same" else dt
        new.name = self.name
        new.states = _names(states if states is not None else
                            (self.states if n == self.n_states else None), n, "z", "state")
        new.outputs = _names(outputs if outputs is not None else self.outputs, p, "y", "output")
        new._groups = {}
        for g in GROUPS:
            Bg, Dg = groups.get(g, (self._groups[g].B, self._groups[g].D))
            new._groups[g] = InputGroup(self._groups[g].names, _mat(Bg, (n, self._groups[g].size), f"B_{g}"),
                                        _mat(Dg, (p, self._groups[g].size), f"D_{g}"))
        return new

    def similarity_transform(self, T: np.ndarray, states: Sequence[str] | None = None) -> LinearFaultModel:
        """New coordinates z = T x: (T A T^-1, T B, C T^-1, D)."""
        T = np.asarray(T, float)
        Ti = np.linalg.solve(T, np.eye(T.shape[0]))
        groups = {g: (T @ self._groups[g].B, self._groups[g].D) for g in GROUPS}
        return self.with_matrices(T @ self.A @ Ti, self.C @ Ti, groups,
                                  states=states or [f"z{i}" for i in range(T.shape[0])])

    def select_outputs(self, names: Iterable[str]) -> LinearFaultModel:
        """The model restricted to some outputs (faults keep their state directions)."""
        idx = self.output_index(names)
        groups = {g: (self._groups[g].B, self._groups[g].D[idx]) for g in GROUPS}
        return self.with_matrices(self.A, self.C[idx], groups, outputs=[self.outputs[i] for i in idx])

    def discretize(self, dt: float, method: str = "zoh") -> LinearFaultModel:
        """Discretise a continuous model with sample time ``dt`` (scipy ``cont2discrete``).

        ``method`` is any method of :func:`scipy.signal.cont2discrete` (``"zoh"``, ``"foh"``,
        ``"bilinear"``, ...). All groups are held constant over a sample (ZOH); for white process
        noise that is the usual first-order approximation.
        """
        from scipy.signal import cont2discrete

        if self.is_discrete:
            raise ModelError(f"model {self.name!r} is already discrete (dt = {self.dt})")
        if not dt > 0:
            raise ModelError(f"dt must be positive, got {dt}")
        Ad, Bd, Cd, Dd, _ = cont2discrete((self.A, self.B_all, self.C, self.D_all), dt, method=method)
        sl = self.group_slices()
        groups = {g: (Bd[:, sl[g]], Dd[:, sl[g]]) for g in GROUPS}
        return self.with_matrices(Ad, Cd, groups, dt=float(dt))

    # ------------------------------------------------------------------ python-control
    def to_statespace(self, groups: Sequence[str] = GROUPS):
        """A :class:`control.StateSpace` with the chosen input groups, names preserved."""
        import control

        sl = self.group_slices()
        cols = np.concatenate([np.arange(sl[g].start, sl[g].stop) for g in groups]).astype(int) \
            if groups else np.zeros(0, int)
        names = [s for g in groups for s in self._groups[g].names]
        B, D = self.B_all[:, cols], self.D_all[:, cols]
        return control.ss(self.A, B, self.C, D, 0 if self.dt is None else self.dt,
                          states=self.states, inputs=names, outputs=self.outputs,
                          name=self.name or None)

    @classmethod
    def from_statespace(
        cls,
        sys: Any,
        *,
        controls: Sequence[str] | None = None,
        disturbances: Sequence[str] = (),
        noises: Sequence[str] = (),
        faults: Iterable[Any] = (),
        name: str | None = None,
    ) -> LinearFaultModel:
        """Build from a :class:`control.StateSpace`, assigning its named inputs to groups.

        Inputs not named in ``disturbances`` or ``noises`` are controls unless ``controls`` is
        given. ``faults`` are then declared on the result.
        """
        in_names = list(sys.input_labels)
        disturbances, noises = list(disturbances), list(noises)
        for s in disturbances + noises + list(controls or []):
            if s not in in_names:
                raise ModelError(f"unknown input {s!r} of the StateSpace; inputs: {in_names}")
        if controls is None:
            controls = [s for s in in_names if s not in disturbances and s not in noises]
        idx = {s: i for i, s in enumerate(in_names)}
        B, D = np.asarray(sys.B), np.asarray(sys.D)

        def cols(names):
            c = [idx[s] for s in names]
            return (B[:, c], D[:, c]) if c else (None, None)

        Bu, Du = cols(controls)
        Bd, Dd = cols(disturbances)
        Bw, Dw = cols(noises)
        n = np.asarray(sys.A).shape[0]
        return cls(sys.A, Bu if Bu is not None else np.zeros((n, 0)), sys.C, Du,
                   dt=None if sys.dt in (0, None) else (None if sys.dt is True else float(sys.dt)),
                   states=list(sys.state_labels), inputs=list(controls), outputs=list(sys.output_labels),
                   Bd=Bd, Dd=Dd, disturbances=disturbances or None, Bw=Bw, Dw=Dw,
                   noises=noises or None, faults=faults, name=name if name is not None else sys.name)

    # ------------------------------------------------------------------ display
    def __repr__(self) -> str:
        kind = "continuous" if self.dt is None else f"discrete dt={self.dt:g} s"
        lines = [f"LinearFaultModel{(' ' + repr(self.name)) if self.name else ''} ({kind}): "
                 f"{self.n_states} states, {self.n_outputs} outputs"]
        lines.append(f"  states:  {', '.join(self.states)}")
        for g in GROUPS:
            if self._groups[g].size:
                lines.append(f"  {_GROUP_NAMES[g] + ':':13s} {', '.join(self._groups[g].names)}")
        lines.append(f"  outputs: {', '.join(self.outputs)}")
        return "\n".join(lines)
