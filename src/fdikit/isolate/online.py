"""Streaming diagnosis from test alarms: one decision per fault episode, by a D-matrix.

A bank of tests (luo-et-al, Section V) fires alarms sample by sample; the announcement an operator
needs is the *diagnosis* -- which fault class, how sure -- once per episode, not every test that
fires or re-arms. :class:`DMatrixDecision` latches the tests that fired since the episode began,
waits until that pattern has been stable for ``settle`` samples, and then decides once, by maximum
likelihood over the D-matrix's learned test reliabilities (the rule of
:func:`fdikit.isolate.diagnose_ml`, luo-et-al Section VII), and holds that decision until the
episode ends (every alarm quiet for ``clear`` samples).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ..base.stage import ResidualProcessor
from ..errors import DataError, ModelError

__all__ = ["DMatrixDecision"]


class DMatrixDecision(ResidualProcessor):
    """Episode diagnosis by a D-matrix: test alarms in, one channel per fault group out.

    Parameters
    ----------
    dmatrix : DMatrix
        Faults x tests, with the probabilities that each test fires under each fault
        (:meth:`~fdikit.isolate.DMatrix.fail_probability`: learned ``pd``/``pf``, or 0/1).
    inputs : sequence of str
        The alarm channel of each test, in the order of ``dmatrix.tests`` (> 0.5 = fired).
    nominal : str, optional
        The no-fault row (excluded from the candidates: a diagnosis is made only once a test has
        fired, the Go path of a diagnostic tree). Default: a row named ``"F0"`` if there is one.
    settle : int
        Samples the latched pattern of fired tests must stay unchanged before the decision
        (tests that fire later, e.g. a slow window or a time-gated test, are waited for).
    clear : int, optional
        Samples with every alarm quiet that end an episode (the latch and the decision are
        reset, the fault channel returns to 0). Default: never (one record, one episode).
    sizes : mapping, optional
        Fault (row name) -> an input channel whose value at the decision is the fault's size
        estimate (e.g. the amplitude of a directional GLRT); output ``<channel>:size``.
    floor : float
        Probabilities are clipped to ``[floor, 1 - floor]`` (a contradicted perfect test counts
        as a factor ``floor``).

    Notes
    -----
    Rows whose firing probabilities are identical cannot be told apart by any outcome: they form
    one output channel, ``fault:A|B``. Every other row has its own channel ``fault:A``. After the
    decision the decided channel holds the posterior probability of its group (uniform prior over
    the non-nominal rows); every other channel is 0. :attr:`announce` maps each channel to its
    announced name and :attr:`size_channels` each channel to its size channel.

    Examples
    --------
    >>> from fdikit.isolate import DMatrix
    >>> dm = DMatrix(["F0", "A", "B"], ["t1", "t2"], [[0, 0], [1, 0], [1, 1]])
    >>> d = DMatrixDecision(dm, ["a1", "a2"], settle=2)
    >>> d.output_names
    ['fault:A', 'fault:B']
    >>> d.reset(1)
    >>> [d.step([x1, x2]).round(3).tolist()[0] for x1, x2 in [(1, 0), (1, 1), (0, 1), (0, 0), (1, 0)]]
    [[0.0, 0.0], [0.0, 0.0], [0.0, 0.0], [0.0, 1.0], [0.0, 1.0]]
    """

    _state_attrs = ("_fired", "_since", "_quiet", "_locked", "_value", "_size")

    def __init__(self, dmatrix: Any, inputs: Sequence[str], *, nominal: str | None = None, settle: int = 100,
                 clear: int | None = None, sizes: Mapping[str, str] | None = None, floor: float = 1e-6):
        self.dmatrix = dmatrix
        faults = [str(f) for f in dmatrix.faults]
        tests = [str(t) for t in dmatrix.tests]
        inputs = [str(s) for s in inputs]
        if len(inputs) != len(tests):
            raise ModelError(f"DMatrixDecision: {len(inputs)} alarm channels {inputs} for the {len(tests)} "
                             f"tests {tests}; give one channel per test, in order")
        if nominal is None:
            nominal = "F0" if "F0" in faults else None
        if nominal is not None and nominal not in faults:
            raise ModelError(f"DMatrixDecision: nominal row {nominal!r} is not among the faults {faults}")
        if int(settle) != settle or settle < 0:
            raise ModelError(f"DMatrixDecision: settle must be an integer >= 0 samples, got {settle}")
        if clear is not None and (int(clear) != clear or clear < 1):
            raise ModelError(f"DMatrixDecision: clear must be an integer >= 1 samples or None, got {clear}")
        if not 0 < floor < 0.5:
            raise ModelError(f"DMatrixDecision: floor must be in (0, 0.5), got {floor}")
        sizes = dict(sizes or {})
        bad = [f for f in sizes if f not in faults or f == nominal]
        if bad:
            raise ModelError(f"DMatrixDecision: sizes name rows {bad} that are not faults of the D-matrix "
                             f"({[f for f in faults if f != nominal]})")
        self.nominal = nominal
        self.settle, self.clear, self.floor = int(settle), None if clear is None else int(clear), float(floor)
        self.tests, self.alarm_names, self.sizes = tests, inputs, sizes
        size_inputs = list(dict.fromkeys(str(c) for c in sizes.values()))
        self.input_names = [*inputs, *[c for c in size_inputs if c not in inputs]]
        p = np.clip(np.asarray(dmatrix.fail_probability(), float), self.floor, 1 - self.floor)
        rows = [i for i, f in enumerate(faults) if f != nominal]
        if not rows:
            raise ModelError("DMatrixDecision: the D-matrix has no fault rows besides the nominal one")
        groups: list[list[int]] = []
        for i in rows:
            for g in groups:
                if np.array_equal(p[g[0]], p[i]):
                    g.append(i)
                    break
            else:
                groups.append([i])
        self.groups = [tuple(faults[i] for i in g) for g in groups]
        self._rows = np.array(rows, np.intp)
        self._row_group = np.array([next(j for j, g in enumerate(groups) if i in g) for i in rows], np.intp)
        self._logp, self._log1mp = np.log(p[self._rows]).T, np.log1p(-p[self._rows]).T   # (n_t, n_rows)
        names = ["|".join(g) for g in self.groups]
        self.fault_channels = [f"fault:{n}" for n in names]
        self.announce = dict(zip(self.fault_channels, names))
        # size: the first row of a group with a size channel gives the group's size
        self._size_src: list[int | None] = []
        for g in self.groups:
            src = next((sizes[f] for f in g if f in sizes), None)
            self._size_src.append(None if src is None else self.input_names.index(str(src)))
        self.size_channels = {ch: f"{ch}:size" for ch, s in zip(self.fault_channels, self._size_src)
                              if s is not None}
        self.output_names = [*self.fault_channels, *self.size_channels.values()]
        self._size_cols = [j for j, s in enumerate(self._size_src) if s is not None]
        self.reset(1)

    # ------------------------------------------------------------------ artifacts
    def to_dict(self) -> dict:
        """Configuration as plain data (see :mod:`fdikit.base.artifacts`)."""
        return {"dmatrix": self.dmatrix.to_dict(), "inputs": list(self.alarm_names), "nominal": self.nominal,
                "settle": self.settle, "clear": self.clear, "sizes": dict(self.sizes), "floor": self.floor}

    @classmethod
    def from_dict(cls, d: Mapping) -> DMatrixDecision:
        from .dmatrix import DMatrix

        return cls(DMatrix.from_dict(d["dmatrix"]), d["inputs"], nominal=d["nominal"], settle=d["settle"],
                   clear=d["clear"], sizes=d["sizes"], floor=d["floor"])

    # ------------------------------------------------------------------ streaming
    def reset(self, runs: int = 1) -> None:
        n = int(runs)
        self._fired = np.zeros((n, len(self.tests)), bool)
        self._since = np.zeros(n, np.int64)
        self._quiet = np.zeros(n, np.int64)
        self._locked = np.full(n, -1, np.int64)
        self._value = np.zeros(n)
        self._size = np.zeros(n)

    def posterior(self, fired: Any) -> np.ndarray:
        """Posterior probability of every group (uniform prior over the fault rows) for latched
        outcomes ``fired`` (runs, n_tests) of 0/1: shape (runs, n_groups)."""
        o = np.atleast_2d(np.asarray(fired, float))
        ll = o @ self._logp + (1 - o) @ self._log1mp                 # (runs, n_rows)
        w = np.exp(ll - ll.max(axis=1, keepdims=True))
        w /= w.sum(axis=1, keepdims=True)
        out = np.zeros((o.shape[0], len(self.groups)))
        for j in range(len(self.groups)):
            out[:, j] = w[:, self._row_group == j].sum(axis=1)
        return out

    def _step(self, r: np.ndarray) -> np.ndarray:
        if r.shape[0] != self._fired.shape[0]:
            raise DataError(f"DMatrixDecision: sample has {r.shape[0]} runs; it was reset for "
                            f"{self._fired.shape[0]}")
        if not np.all(np.isfinite(r)):
            run, c = np.argwhere(~np.isfinite(r))[0]
            raise DataError(f"DMatrixDecision: input channel {self.input_names[c]!r} is not finite "
                            f"(run {run})")
        on = r[:, :len(self.tests)] > 0.5
        new = (on & ~self._fired).any(axis=1)
        self._fired |= on
        anyf = self._fired.any(axis=1)
        self._since = np.where(new, 0, np.where(anyf, self._since + 1, 0))
        self._quiet = np.where(on.any(axis=1), 0, self._quiet + 1)
        ready = (self._locked < 0) & anyf & (self._since >= self.settle)
        if ready.any():
            post = self.posterior(self._fired[ready])
            best = post.argmax(axis=1)
            self._locked[ready] = best
            self._value[ready] = post[np.arange(len(best)), best]
            src = np.array([-1 if s is None else s for s in self._size_src])[best]
            self._size[ready] = np.where(src >= 0, r[ready, np.maximum(src, 0)], 0.0)
        if self.clear is not None:
            done = anyf & (self._quiet >= self.clear)
            if done.any():
                self._fired[done] = False
                self._since[done] = 0
                self._locked[done] = -1
                self._value[done] = 0.0
                self._size[done] = 0.0
        out = np.zeros((r.shape[0], len(self.output_names)))
        runs = np.flatnonzero(self._locked >= 0)
        out[runs, self._locked[runs]] = self._value[runs]
        for k, j in enumerate(self._size_cols):
            sel = runs[self._locked[runs] == j]
            out[sel, len(self.groups) + k] = self._size[sel]
        return out

    def __repr__(self) -> str:
        return (f"DMatrixDecision(groups={['|'.join(g) for g in self.groups]}, tests={self.tests}, "
                f"settle={self.settle}, clear={self.clear})")
