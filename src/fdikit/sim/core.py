"""Fixed-step simulation of many runs at once, with faults, noise, sampled sensors and controllers.

The engine advances a state array of shape ``(runs, n)`` on the integration grid
``t_k = k dt`` (k = 0..N), with every input held constant over a step (zero-order hold):

* a :class:`~fdikit.model.LinearFaultModel` steps with its exact ZOH discretisation at ``dt``
  (continuous time) or at its own sample time (discrete time);
* a nonlinear model (``f(t, x, u, p)``, ``h(t, x, u, p)`` vectorised over runs) steps with
  classical fixed-step RK4 (default) or forward Euler.

Measurements are taken every ``sample_time = ratio * dt`` and held in between (paper
luo-et-al, eq. (31)); sensor faults act on the clean measurement, then white measurement
noise is added. A controller ``u = controller(t, y)`` runs at the measurement rate on these
noisy, faulty measurements; its output is held, and actuator faults act between it and the
plant.

Process noise (see :class:`~fdikit.faults.Noise` for the exact discretisation): by default
(``process_mode="derivative"``) a random signal held over each integration step is added to
``x'`` -- RK4 treats it as a constant input over the step, linear models integrate it exactly
through ``int_0^dt exp(A s) ds``; ``"psd"`` adds Euler--Maruyama increments ``sqrt(dt) L z``
for a white-noise intensity ``Q = L L'``; ``"increment"`` adds ``L z`` after each step (the
only mode of discrete-time models). Noise inputs (group ``w``) declared on a linear model are
not driven: process noise enters every state directly.

Determinism. Run ``i`` draws its noise from its own streams,
``Generator(PCG64(SeedSequence(seed, spawn_key=(i, 0))))`` for process noise and
``spawn_key=(i, 1)`` for measurement noise, in time chunks (the chunk length only bounds memory:
consecutive draws from one stream do not depend on how they are split). Every operation of the
engine is elementwise across runs (linear models use an explicit column-by-column product,
never BLAS), so run ``i`` gives bitwise the same numbers alone (``run_ids=[i]``) or inside a
batch of any size -- provided the model's ``f``/``h`` and the controller are elementwise across
runs too.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import DataError, ModelError
from ..faults import FaultInjector, Noise, Scenario, per_run
from ..faults.signals import parse_target
from ..model.linear import LinearFaultModel
from ..signals import Signals

__all__ = ["METHODS", "SimResult", "SimulationError", "sample_and_hold", "simulate"]

#: Integration methods of nonlinear models.
METHODS = ("rk4", "euler")
_KEEP = ("y", "x", "u")
#: Noise buffers are refilled in chunks of at most this many bytes (per stream).
_CHUNK_BYTES = 48 * 2**20


class SimulationError(ModelError):
    """The simulation produced NaN or inf, or a model returned arrays of the wrong shape."""


@dataclass
class SimResult:
    """What :func:`simulate` returns.

    Attributes
    ----------
    y : Signals
        Measurements at the measurement rate, values (runs, T, p): sensor faults and noise
        included. ``t = 0, sample_time, ..., duration``.
    x : Signals or None
        True states at the measurement times (runs, T, n), when kept.
    u : Signals or None
        Commanded control inputs (what the controller or the input trajectory sent, i.e. what a
        diagnoser knows; actuator faults are *not* in it) at the measurement times, when kept.
    run_ids : ndarray of int, shape (runs,)
    seed : int
    dt, sample_time : float
        Integration step and measurement sample time (s).
    method : str
    process_std : ndarray or None
        Standard deviations of the process noise, (runs, n) (per run, per state), or the
        factor ``L`` (n, n) with ``L L' = Q`` for a full covariance.
    measurement_std : ndarray or None
        Same for the measurement noise, (runs, p) or (p, p).
    nominal_ms : dict
        Mean-square values of the nominal pass used for SNR noise: ``{"x": (runs, n),
        "y": (runs, p)}`` (empty when no SNR was asked).
    """

    y: Signals
    x: Signals | None
    u: Signals | None
    run_ids: np.ndarray
    seed: int
    dt: float
    sample_time: float
    method: str
    process_std: np.ndarray | None = None
    measurement_std: np.ndarray | None = None
    nominal_ms: dict = field(default_factory=dict)

    @property
    def t(self) -> np.ndarray:
        return self.y.t

    @property
    def runs(self) -> int:
        return self.y.runs

    def signals(self) -> Signals:
        """Commanded inputs and measurements joined, ``u`` channels first (what a residual
        generator consumes). Needs ``"u"`` in ``keep``."""
        if self.u is None:
            raise DataError("inputs were not kept: simulate(..., keep=('y', 'u'))")
        return self.u.concat_channels(self.y)

    def __repr__(self) -> str:
        kept = [k for k in _KEEP if getattr(self, k) is not None]
        return (f"SimResult(runs={self.runs}, samples={self.y.n_samples}, dt={self.dt:g} s, "
                f"sample_time={self.sample_time:g} s, method={self.method!r}, kept={kept})")


def sample_and_hold(signals: Signals, t: Any) -> Signals:
    """Zero-order hold of sampled signals onto another time grid (luo-et-al, eq. (31)).

    ``y_h(t) = y(t_k)`` for ``t_k <= t < t_(k+1)``.

    Parameters
    ----------
    signals : Signals
        Samples at times ``t_k``, values (runs, K, c).
    t : array_like, shape (T,)
        New times (s), none before the first sample.

    Returns
    -------
    Signals
        Values (runs, T, c).

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit import Signals
    >>> s = Signals([0.0, 0.1, 0.2], [[1.0], [2.0], [3.0]], ["y"])
    >>> sample_and_hold(s, np.arange(6) * 0.05).values[0, :, 0].tolist()
    [1.0, 1.0, 2.0, 2.0, 3.0, 3.0]
    """
    t = np.asarray(t, dtype=float).reshape(-1)
    tk = signals.t
    tol = 1e-9 * max(1.0, float(np.abs(tk).max()) if tk.size else 1.0)
    if t.size and t.min() < tk[0] - tol:
        raise DataError(f"sample_and_hold: time {t.min():g} s is before the first sample ({tk[0]:g} s)")
    idx = np.clip(np.searchsorted(tk, t + tol, side="right") - 1, 0, tk.size - 1)
    return Signals(t, signals.values[:, idx, :], signals.names, signals.units, check=False)


# ====================================================================== helpers
def _mv_acc(M: np.ndarray, X: np.ndarray, out: np.ndarray, cols: Sequence[int]) -> None:
    """``out += X @ M.T`` column by column (elementwise across runs, hence run-size independent).

    M (r, c), X (runs, c), out (runs, r); ``cols`` lists the non-zero columns of M.
    """
    for j in cols:
        out += X[:, j : j + 1] * M[:, j]


class _Store:
    """Collects (runs, c) samples into a (runs, T, c) array through a time-major buffer (the
    direct strided write of 5000 rows per sample is an order of magnitude slower)."""

    def __init__(self, runs: int, T: int, c: int, block: int = 256):
        self.out = np.empty((runs, T, c))
        self.buf = np.empty((min(block, T), runs, c))
        self.j0, self.n = 0, 0

    def put(self, j: int, v: np.ndarray) -> None:
        self.buf[self.n] = v
        self.n += 1
        if self.n == self.buf.shape[0]:
            self.flush()

    def flush(self) -> None:
        if self.n:
            self.out[:, self.j0 : self.j0 + self.n, :] = self.buf[: self.n].transpose(1, 0, 2)
            self.j0 += self.n
            self.n = 0


def _nz_cols(M: np.ndarray) -> list[int]:
    return [j for j in range(M.shape[1]) if np.any(M[:, j] != 0.0)]


class _Source:
    """An input trajectory: constant, on the integration grid, per run, or a callable of t."""

    def __init__(self, spec: Any, names: Sequence[str], n_steps: int, ids: np.ndarray,
                 total: int | None, what: str):
        self.m, self.runs, self.what = len(names), ids.size, what
        self.fn: Callable | None = None
        self.const: np.ndarray | None = None
        self.arr: np.ndarray | None = None
        m = self.m
        if spec is None:
            self.const = np.zeros((self.runs, m))
            return
        if callable(spec):
            self.fn = spec
            return
        a = np.asarray(spec, dtype=float)
        if not np.all(np.isfinite(a)):
            bad = np.argwhere(~np.isfinite(a))[0].tolist()
            raise DataError(f"{what} contain NaN or inf at index {bad}")
        T = n_steps + 1
        if a.ndim == 0 and m == 1:
            a = a.reshape(1)
        if a.ndim == 1 and a.size == m:
            self.const = np.broadcast_to(a, (self.runs, m))
        elif a.ndim == 1 and m == 1 and a.size in (T, T - 1):
            self.arr = a.reshape(1, -1, 1)
        elif a.ndim == 2 and a.shape[1] == m and a.shape[0] in (T, T - 1):
            self.arr = a[None]
        elif a.ndim == 3 and a.shape[2] == m and a.shape[1] in (T, T - 1):
            if total is not None and a.shape[0] != total:
                raise DataError(f"{what} have {a.shape[0]} runs but the batch has {total}")
            if int(ids.max()) >= a.shape[0]:
                raise DataError(f"{what} have {a.shape[0]} runs but run id {int(ids.max())} was requested")
            self.arr = a[ids]
        else:
            raise DataError(
                f"{what} have shape {a.shape}; expected ({m},) constant, ({T}, {m}) on the integration "
                f"grid (N + 1 = {T} steps), (runs, {T}, {m}) per run, or a callable t -> ({m},) "
                f"for channels {list(names)}")
        if self.arr is not None:
            self.arr = np.ascontiguousarray(np.swapaxes(self.arr, 0, 1))  # (T, runs|1, m)

    def at(self, k: int, t: float) -> np.ndarray:
        if self.const is not None:
            return self.const
        if self.arr is not None:
            a = self.arr[min(k, self.arr.shape[0] - 1)]
            return a if a.shape[0] == self.runs else np.broadcast_to(a, (self.runs, self.m))
        v = np.asarray(self.fn(t), dtype=float)  # type: ignore[misc]
        if v.shape != (self.m,) and not (self.m == 1 and v.ndim == 0):
            raise DataError(f"{self.what} callable returned shape {v.shape} at t = {t:g} s; "
                            f"expected ({self.m},)")
        if not np.all(np.isfinite(v)):
            raise DataError(f"{self.what} callable returned NaN or inf at t = {t:g} s: {v.tolist()}")
        return np.broadcast_to(v.reshape(self.m), (self.runs, self.m))

    @property
    def per_run(self) -> bool:
        return self.arr is not None and self.arr.shape[1] > 1


class _NoiseStream:
    """Standard normal draws (runs, k) per time index from one generator per run, in chunks.

    Each run's generator fills its own contiguous (chunk, k) block (``out=`` needs a contiguous
    target); a time index is then gathered into a column-major (runs, k) array like the
    engine's state (a gather per step is cheaper here than transposing whole chunks). The
    returned array is reused at the next call.
    """

    def __init__(self, seed: int, ids: np.ndarray, stream: int, k: int, n_total: int):
        self.gens = [np.random.Generator(np.random.PCG64(
            np.random.SeedSequence(seed, spawn_key=(int(i), stream)))) for i in ids]
        self.k = k
        self.chunk = int(max(1, min(n_total, _CHUNK_BYTES // max(1, 8 * k * len(self.gens)))))
        self.buf = np.empty((len(self.gens), self.chunk, k))
        self.z = np.empty((len(self.gens), k), order="F")
        self.pos = self.chunk

    def next(self) -> np.ndarray:
        if self.pos == self.chunk:
            for r, g in enumerate(self.gens):
                g.standard_normal(out=self.buf[r])
            self.pos = 0
        np.copyto(self.z, self.buf[:, self.pos, :])
        self.pos += 1
        return self.z


class _Scaler:
    """Scales standard normals by per-run std (runs, k) or by a full factor L (k, k)."""

    def __init__(self, std: np.ndarray | None, L: np.ndarray | None):
        self.std, self.L = std, L
        self.cols = _nz_cols(L) if L is not None else []

    def __call__(self, z: np.ndarray) -> np.ndarray:
        if self.L is None:
            return z * self.std
        out = np.zeros((z.shape[0], self.L.shape[0]))
        _mv_acc(self.L, z, out, self.cols)
        return out


def _factor(cov: Any, k: int, what: str, names: Sequence[str]) -> tuple[np.ndarray | None, np.ndarray | None]:
    """(std (1, k), None) for variances / diagonal covariance, (None, L) for a full covariance."""
    a = np.asarray(cov, dtype=float)
    if a.ndim == 0:
        a = a.reshape(1)
    if a.shape not in ((k,), (k, k)):
        raise DataError(f"{what} has shape {a.shape}; expected ({k},) variances or ({k}, {k}) covariance "
                        f"for channels {list(names)}")
    if a.ndim == 1:
        return np.sqrt(a)[None, :], None
    if np.count_nonzero(a - np.diag(np.diag(a))) == 0:
        return np.sqrt(np.diag(a))[None, :], None
    lam, V = np.linalg.eigh(a)
    return None, V * np.sqrt(np.clip(lam, 0.0, None))


def _snr_std(ms: np.ndarray, snr: Any, k: int, what: str, names: Sequence[str]) -> np.ndarray:
    s = np.atleast_1d(np.asarray(snr, dtype=float))
    if s.size == 1:
        s = np.full(k, s[0])
    if s.shape != (k,):
        raise DataError(f"{what} has {s.size} values; expected 1 or {k} (channels {list(names)})")
    var = ms * 10.0 ** (-s / 10.0)  # luo-et-al: variance = 0.5 % of the mean square at 23 dB
    return np.sqrt(var)


def _locate_bad(a: np.ndarray) -> tuple[int, int]:
    r, j = np.argwhere(~np.isfinite(a))[0]
    return int(r), int(j)


# ====================================================================== plants
class _Plant:
    """Common interface of the linear and nonlinear plants."""

    name: str
    states: list[str]
    outputs: list[str]
    controls: list[str]
    disturbances: list[str]
    fault_inputs: list[str]
    params: dict[str, float]
    dt: float
    discrete: bool = False

    def step(self, t, x, u, d, f, p, w):  # pragma: no cover - interface
        raise NotImplementedError

    def output(self, t, x, u, d, f, p):  # pragma: no cover - interface
        raise NotImplementedError


class _LinearPlant(_Plant):
    def __init__(self, model: LinearFaultModel, scenario: Scenario, derivative_noise: bool):
        self.name = model.name
        self.states, self.outputs = list(model.states), list(model.outputs)
        self.controls, self.disturbances = model.input_names("u"), model.input_names("d")
        fnames = model.fault_names
        fidx = [i for i, s in enumerate(fnames) if parse_target(s)[0] not in ("actuator", "sensor")]
        self.fault_inputs = [fnames[i] for i in fidx]
        self.params = {}
        Bu, Bd, Bf = model.B_of("u"), model.B_of("d"), model.B_of("f")[:, fidx]
        self.Du, self.Dd, self.Df = model.D_of("u"), model.D_of("d"), model.D_of("f")[:, fidx]
        self.C = model.C
        n = model.n_states
        if model.is_discrete:
            if scenario.dt is not None and abs(scenario.dt - model.dt) > 1e-12 * model.dt:
                raise DataError(f"Scenario dt = {scenario.dt} s but the discrete model {model.name!r} "
                                f"steps at its own dt = {model.dt} s (give dt=None or the same value)")
            self.dt, self.discrete = float(model.dt), True
            self.Ad, self.Gu, self.Gd, self.Gf, self.Gw = model.A, Bu, Bd, Bf, np.eye(n)
        else:
            from scipy.linalg import expm

            self.dt = scenario.grid()[0]
            blocks = [Bu, Bd, Bf, np.eye(n)]
            q = sum(b.shape[1] for b in blocks)
            M = np.zeros((n + q, n + q))
            M[:n, :n] = model.A
            M[:n, n:] = np.hstack(blocks)
            E = expm(M * self.dt)  # exact ZOH: [[Ad, int_0^dt e^{As} ds B], [0, I]]
            self.Ad = E[:n, :n]
            G, k = E[:n, n:], 0
            out = []
            for b in blocks:
                out.append(G[:, k : k + b.shape[1]])
                k += b.shape[1]
            self.Gu, self.Gd, self.Gf, self.Gw = out
        self.derivative_noise = derivative_noise
        self._cols = {k: _nz_cols(M) for k, M in (("A", self.Ad), ("u", self.Gu), ("d", self.Gd),
                                                  ("f", self.Gf), ("w", self.Gw), ("C", self.C),
                                                  ("Du", self.Du), ("Dd", self.Dd), ("Df", self.Df))}

    def step(self, t, x, u, d, f, p, w):
        out = np.zeros_like(x)
        c = self._cols
        _mv_acc(self.Ad, x, out, c["A"])
        _mv_acc(self.Gu, u, out, c["u"])
        _mv_acc(self.Gd, d, out, c["d"])
        _mv_acc(self.Gf, f, out, c["f"])
        if w is not None:
            _mv_acc(self.Gw, w, out, c["w"])
        return out

    def output(self, t, x, u, d, f, p):
        out = np.zeros((x.shape[0], self.C.shape[0]))
        c = self._cols
        _mv_acc(self.C, x, out, c["C"])
        _mv_acc(self.Du, u, out, c["Du"])
        _mv_acc(self.Dd, d, out, c["Dd"])
        _mv_acc(self.Df, f, out, c["Df"])
        return out


class _NonlinearPlant(_Plant):
    def __init__(self, model: Any, scenario: Scenario, method: str):
        for attr in ("f", "h", "states", "inputs", "outputs"):
            if not hasattr(model, attr):
                raise ModelError(f"model {model!r} is neither a LinearFaultModel nor a nonlinear model "
                                 f"(missing attribute {attr!r}; needs f, h, states, inputs, outputs, params)")
        if method not in METHODS:
            raise DataError(f"unknown integration method {method!r}; use one of {METHODS}")
        self.model, self.method = model, method
        self.name = str(getattr(model, "name", ""))
        self.states, self.outputs = list(model.states), list(model.outputs)
        self.inputs = list(model.inputs)
        groups = getattr(model, "groups", None) or {}
        other = set(groups.get("d", ())) | set(groups.get("w", ()))
        self.controls = list(groups.get("u") or [s for s in self.inputs if s not in other])
        self.disturbances = list(groups.get("d", ()))
        self.fault_inputs = []
        self.params = dict(getattr(model, "params", {}) or {})
        self.dt = scenario.grid()[0]
        idx = {s: i for i, s in enumerate(self.inputs)}
        self.iu = [idx[s] for s in self.controls]
        self.id = [idx[s] for s in self.disturbances]
        self.direct = self.iu == list(range(len(self.inputs)))  # u is the whole input vector
        self._checked = False

    def _full_u(self, u, d):
        if self.direct:
            return u
        full = np.zeros((u.shape[0], len(self.inputs)))
        full[:, self.iu] = u
        if self.id:
            full[:, self.id] = d
        return full

    def _f(self, t, x, u, p, w):
        dx = self.model.f(t, x, u, p)
        if not self._checked:
            dx = np.asarray(dx)
            if dx.shape != x.shape:
                raise SimulationError(f"model {self.name!r}: f returned shape {dx.shape}, expected "
                                      f"{x.shape} (runs, n) for states {self.states}")
            self._checked = True
        if w is not None:
            dx = dx + w
        return dx

    def step(self, t, x, u, d, f, p, w):
        h = self.dt
        uf = self._full_u(u, d)
        if self.method == "euler":
            k1 = self._f(t, x, uf, p, w)
            k1 = k1 * h
            k1 += x
            return k1
        hh = 0.5 * h
        k1 = self._f(t, x, uf, p, w)
        xt = k1 * hh
        xt += x
        k2 = self._f(t + hh, xt, uf, p, w)
        np.multiply(k2, hh, out=xt)
        xt += x
        k3 = self._f(t + hh, xt, uf, p, w)
        np.multiply(k3, h, out=xt)
        xt += x
        k4 = self._f(t + h, xt, uf, p, w)
        # x + h/6 (k1 + 2 k2 + 2 k3 + k4), classical RK4
        np.add(k2, k3, out=xt)
        xt *= 2.0
        xt += k1
        xt += k4
        xt *= h / 6.0
        xt += x
        return xt

    def output(self, t, x, u, d, f, p):
        y = np.asarray(self.model.h(t, x, self._full_u(u, d), p), dtype=float)
        if y.shape != (x.shape[0], len(self.outputs)):
            raise SimulationError(f"model {self.name!r}: h returned shape {y.shape}, expected "
                                  f"({x.shape[0]}, {len(self.outputs)}) for outputs {self.outputs}")
        return y


# ====================================================================== engine
@dataclass
class _Pass:
    """Configuration of one pass of the engine."""

    ids: np.ndarray
    total: int | None
    injector: FaultInjector | None = None
    proc: _Scaler | None = None
    proc_mode: str = "derivative"
    meas: _Scaler | None = None
    seed: int = 0
    keep: tuple[str, ...] = ()
    y_cols: list[int] = field(default_factory=list)
    collect_ms: bool = False


def _x0(plant: _Plant, model: Any, sc: Scenario, ids: np.ndarray, total: int | None) -> np.ndarray:
    n = len(plant.states)
    x0 = sc.x0 if sc.x0 is not None else getattr(model, "x0", None)
    if x0 is None:
        return np.zeros((ids.size, n))
    a = np.asarray(x0, dtype=float)
    if a.shape == (n,):
        x = np.broadcast_to(a, (ids.size, n)).copy()
    elif a.ndim == 2 and a.shape[1] == n:
        if total is not None and a.shape[0] != total:
            raise DataError(f"x0 has {a.shape[0]} rows (runs) but the batch has {total} runs")
        if int(ids.max()) >= a.shape[0]:
            raise DataError(f"x0 has {a.shape[0]} rows but run id {int(ids.max())} was requested")
        x = a[ids].copy()
    else:
        raise DataError(f"x0 has shape {a.shape}; expected ({n},) or (runs, {n}) for states {plant.states}")
    if not np.all(np.isfinite(x)):
        r, j = _locate_bad(x)
        raise DataError(f"x0 of state {plant.states[j]!r} is {x[r, j]} for run id {int(ids[r])}")
    return x


def _params(plant: _Plant, sc: Scenario, ids: np.ndarray, total: int | None) -> dict[str, Any]:
    p = dict(plant.params)
    for k, v in (sc.params or {}).items():
        if k not in p:
            raise DataError(f"Scenario params: unknown parameter {k!r} of model {plant.name!r}; "
                            f"parameters: {sorted(p)}")
        p[k] = per_run(v, ids, total, f"parameter {k!r}")
    return p


def _run(plant: _Plant, model: Any, sc: Scenario, cfg: _Pass) -> dict[str, Any]:
    """One pass over the time grid. Returns stored arrays and mean squares."""
    dt, ratio, N, Tm = sc.grid(plant.dt)
    ids, total = cfg.ids, cfg.total
    runs = ids.size
    n, nu, ny = len(plant.states), len(plant.controls), len(plant.outputs)
    # the state is kept column-major: x[:, i] (one state of every run) is contiguous, which is
    # what vectorised models read; the model sees the usual (runs, n) array
    x = np.asfortranarray(_x0(plant, model, sc, ids, total))
    p_nom = _params(plant, sc, ids, total)
    usrc = _Source(sc.inputs, plant.controls, N, ids, total, "Scenario inputs")
    dsrc = _Source(sc.disturbances, plant.disturbances, N, ids, total, "Scenario disturbances")
    inj = cfg.injector
    eps = 1e-6 * dt
    if inj is not None:
        inj.bind(ids, total, eps=eps)
    has_act = inj is not None and inj.has("actuator")
    has_sen = inj is not None and inj.has("sensor")
    has_par = inj is not None and inj.has("param")
    has_fin = inj is not None and inj.has("input")
    f_zero = np.zeros((runs, len(plant.fault_inputs)))
    ctrl = sc.controller
    if ctrl is not None and hasattr(ctrl, "reset"):
        ctrl.reset(runs)

    keep = cfg.keep
    store: dict[str, _Store] = {}
    if "y" in keep:
        store["y"] = _Store(runs, Tm, len(cfg.y_cols))
    if "x" in keep:
        store["x"] = _Store(runs, Tm, n)
    if "u" in keep:
        store["u"] = _Store(runs, Tm, nu)
    y_all_cols = cfg.y_cols == list(range(ny))

    proc_z = meas_z = None
    if cfg.proc is not None:
        proc_z = _NoiseStream(cfg.seed, ids, 0, n, N)
    if cfg.meas is not None:
        meas_z = _NoiseStream(cfg.seed, ids, 1, ny, Tm)
    deriv_noise = cfg.proc is not None and cfg.proc_mode == "derivative"
    post_scale = 1.0 if cfg.proc_mode == "increment" else np.sqrt(dt)

    ms_x = np.zeros((runs, n)) if cfg.collect_ms else None
    ms_y = np.zeros((runs, ny)) if cfg.collect_ms else None
    if ms_x is not None:
        ms_x += x * x

    u_cmd = np.zeros((runs, nu))
    u_true = u_prev = u_cmd
    for k in range(N + 1):
        t = k * dt
        p = inj.params(t, p_nom) if has_par else p_nom
        d = dsrc.at(k, t)
        fv = inj.fault_inputs(t, runs) if has_fin else f_zero
        if ctrl is None:
            u_cmd = usrc.at(k, t)
            u_true = inj.actuator(t, u_cmd) if has_act else u_cmd
        if k % ratio == 0:
            j = k // ratio
            y = plant.output(t, x, u_true if ctrl is None else u_prev, d, fv, p)
            if not np.isfinite(y).all():
                r, c = _locate_bad(y)
                raise SimulationError(f"model {plant.name!r}: output {plant.outputs[c]!r} is {y[r, c]} in "
                                      f"run {r} (run id {int(ids[r])}) at t = {t:.6g} s")
            if ms_y is not None:
                ms_y += y * y
            if has_sen:
                y = inj.sensor(t, y)
            if meas_z is not None:
                y = y + cfg.meas(meas_z.next())
            if "y" in store:
                store["y"].put(j, y if y_all_cols else y[:, cfg.y_cols])
            if "x" in store:
                store["x"].put(j, x)
            if ctrl is not None:
                uc = np.asarray(ctrl(t, y), dtype=float)
                if uc.shape == (nu,):
                    uc = np.broadcast_to(uc, (runs, nu))
                if uc.shape != (runs, nu):
                    raise DataError(f"controller returned shape {uc.shape} at t = {t:g} s; expected "
                                    f"({runs}, {nu}) or ({nu},) for inputs {plant.controls}")
                if not np.isfinite(uc).all():
                    r, c = _locate_bad(uc)
                    raise SimulationError(f"controller output {plant.controls[c]!r} is {uc[r, c]} in run {r} "
                                          f"(run id {int(ids[r])}) at t = {t:.6g} s")
                u_cmd = uc
            if "u" in store:
                store["u"].put(j, u_cmd)
        if k == N:
            break
        if ctrl is not None:
            u_true = inj.actuator(t, u_cmd) if has_act else u_cmd
        w = cfg.proc(proc_z.next()) if deriv_noise else None
        x = plant.step(t, x, u_true, d, fv, p, w)
        if proc_z is not None and not deriv_noise:
            x += post_scale * cfg.proc(proc_z.next())
        if not np.isfinite(x).all():
            r, c = _locate_bad(x)
            raise SimulationError(
                f"model {plant.name!r}: state {plant.states[c]!r} became {x[r, c]} in run {r} "
                f"(run id {int(ids[r])}) at t = {t + dt:.6g} s (step {k + 1} of {N}, dt = {dt:g} s)")
        if ms_x is not None:
            ms_x += x * x
        u_prev = u_true
    out: dict[str, Any] = {}
    for key, st in store.items():
        st.flush()
        out[key] = st.out
    if cfg.collect_ms:
        out["ms_x"] = ms_x / (N + 1)
        out["ms_y"] = ms_y / Tm
    return out


def _nominal_is_common(plant: _Plant, model: Any, sc: Scenario, N: int) -> bool:
    """Whether all runs share the same nominal (fault-free, noise-free) trajectory."""
    x0 = sc.x0 if sc.x0 is not None else getattr(model, "x0", None)
    if x0 is not None and np.ndim(x0) == 2:
        return False
    if any(np.ndim(v) > 0 for v in (sc.params or {}).values()):
        return False
    for spec in (sc.inputs, sc.disturbances):
        if spec is not None and not callable(spec) and np.ndim(spec) == 3:
            return False
    return True


def simulate(
    model: Any,
    scenario: Scenario,
    runs: int | None = None,
    seed: int = 0,
    *,
    run_ids: Sequence[int] | None = None,
    method: str = "rk4",
    outputs: Sequence[str] | None = None,
    keep: Sequence[str] = ("y", "u"),
) -> SimResult:
    """Simulate ``runs`` Monte Carlo runs of a model in one vectorised pass.

    Parameters
    ----------
    model : LinearFaultModel or nonlinear model
        A :class:`~fdikit.model.LinearFaultModel` (continuous: exact ZOH discretisation at
        ``scenario.dt``; discrete: steps at its own ``dt``; declared fault inputs are driven by
        additive faults targeting their names), or an object with ``f(t, x, u, p)``,
        ``h(t, x, u, p)`` vectorised over runs, ``states``, ``inputs``, ``outputs``, ``params``
        (:class:`~fdikit.model.NonlinearModel`).
    scenario : ~fdikit.faults.Scenario
        Duration, steps, faults, initial state, inputs or controller, noise, parameters.
    runs : int, optional
        Number of runs (ids ``0..runs-1``); default 1, or ``len(run_ids)``.
    seed : int
        Root seed. Run ``i`` draws from ``SeedSequence(seed, spawn_key=(i, stream))``.
    run_ids : sequence of int, optional
        Simulate these run ids (e.g. ``[17]`` reproduces run 17 of a 5000-run batch bitwise).
        Per-run arrays in the scenario (magnitudes, params, x0, inputs) are indexed by run id.
    method : {"rk4", "euler"}
        Fixed-step integrator of nonlinear models (ignored for linear models).
    outputs : sequence of str, optional
        Output channels to return in ``.y`` (default all; a controller always sees all).
    keep : sequence of {"y", "x", "u"}
        What to store (memory: 5000 runs x 12 501 samples x 8 channels is 4 GB).

    Returns
    -------
    SimResult
        ``.y`` measurements (runs, T, p) at ``t = 0, sample_time, ..., duration``; ``.x`` true
        states and ``.u`` commanded inputs at the same times, when kept.

    Notes
    -----
    Per integration step ``[t_k, t_k + dt)``: parameters (with parametric faults), the input
    (with actuator faults) and the process noise are evaluated at ``t_k`` and held. At a
    measurement time the output ``h(t_k, x_k, u, p)`` is taken (with a controller: ``u`` is the
    input held over the previous step, so there is no algebraic loop), sensor faults act on
    it, then measurement noise is added; the controller then computes the input held until the
    next measurement. SNR noise levels come from a nominal pass (no faults, no noise) of the
    same runs: ``variance = ms * 10**(-snr/10)`` with ``ms`` each state's mean square over the
    integration grid (each output's over the measurement samples). See :class:`Noise` for how
    process noise is discretised.

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit.model import LinearFaultModel
    >>> from fdikit.faults import Bias, Scenario
    >>> from fdikit.sim import simulate
    >>> m = LinearFaultModel([[-1.0]], [[1.0]], [[1.0]], states=["v"], inputs=["thr"], outputs=["v_m"])
    >>> sc = Scenario(duration=2.0, dt=0.01, sample_time=0.1, inputs=[1.0],
    ...               faults=[Bias("sensor:v_m", 0.5, start=1.0)])
    >>> r = simulate(m, sc, runs=3)
    >>> r.y.values.shape, round(float(r.y["v_m"][0, -1]), 4)   # 1 - exp(-2) + 0.5
    ((3, 21, 1), 1.3647)
    """
    if not isinstance(scenario, Scenario):
        raise DataError(f"scenario must be a Scenario, got {type(scenario).__name__}")
    if run_ids is None:
        R = 1 if runs is None else int(runs)
        if R < 1:
            raise DataError(f"runs must be >= 1, got {runs}")
        ids, total = np.arange(R), R
    else:
        ids = np.asarray(run_ids).reshape(-1)
        if ids.size == 0 or ids.dtype.kind not in "iu" or ids.min() < 0:
            raise DataError(f"run_ids must be non-negative integers, got {run_ids!r}")
        ids = ids.astype(np.int64)
        if runs is not None and int(runs) != ids.size:
            raise DataError(f"runs = {runs} but {ids.size} run_ids were given")
        total = None
    keep = tuple(keep)
    for k in keep:
        if k not in _KEEP:
            raise DataError(f"keep has unknown item {k!r}; choose from {_KEEP}")
    if "y" not in keep:
        keep = ("y", *keep)
    noise = scenario.noise or Noise()
    if isinstance(model, LinearFaultModel):
        mode = noise.process_mode or ("increment" if model.is_discrete else "derivative")
        if model.is_discrete and mode != "increment":
            raise DataError(f"process_mode {mode!r} needs continuous time; a discrete-time model takes "
                            "process noise as a per-step increment (process_mode='increment')")
        plant: _Plant = _LinearPlant(model, scenario, derivative_noise=mode == "derivative")
        method = "zoh-exact"
    else:
        mode = noise.process_mode or "derivative"
        plant = _NonlinearPlant(model, scenario, method)
    dt, ratio, N, Tm = scenario.grid(plant.dt)
    injector = FaultInjector(scenario.faults, inputs=plant.controls, outputs=plant.outputs,
                             params=list(plant.params), fault_inputs=plant.fault_inputs,
                             model_name=plant.name)
    injector.bind(ids, total)  # validates per-run magnitudes before any work
    if outputs is None:
        y_cols = list(range(len(plant.outputs)))
    else:
        y_cols = []
        for s in outputs:
            if s not in plant.outputs:
                raise DataError(f"unknown output {s!r} of model {plant.name!r}; outputs: {plant.outputs}")
            y_cols.append(plant.outputs.index(s))

    n, ny = len(plant.states), len(plant.outputs)
    nominal: dict[str, Any] = {}
    need_ms = noise.process_snr_db is not None or noise.measurement_snr_db is not None
    with np.errstate(all="ignore"):
        if need_ms:
            common = _nominal_is_common(plant, model, scenario, N)
            nom_ids = ids[:1] if common else ids
            res = _run(plant, model, scenario, _Pass(ids=nom_ids, total=None if common else total,
                                                     collect_ms=True))
            nominal = {"x": np.broadcast_to(res["ms_x"], (ids.size, n)).copy(),
                       "y": np.broadcast_to(res["ms_y"], (ids.size, ny)).copy()}
        proc = meas = None
        proc_std = meas_std = None
        if noise.process is not None:
            std, L = _factor(noise.process, n, "process noise", plant.states)
            proc, proc_std = _Scaler(std, L), (std if L is None else L)
        elif noise.process_snr_db is not None:
            std = _snr_std(nominal["x"], noise.process_snr_db, n, "process_snr_db", plant.states)
            proc, proc_std = _Scaler(std, None), std
        if noise.measurement is not None:
            std, L = _factor(noise.measurement, ny, "measurement noise", plant.outputs)
            meas, meas_std = _Scaler(std, L), (std if L is None else L)
        elif noise.measurement_snr_db is not None:
            std = _snr_std(nominal["y"], noise.measurement_snr_db, ny, "measurement_snr_db", plant.outputs)
            meas, meas_std = _Scaler(std, None), std
        if proc_std is not None and proc_std.shape[0] == 1 and proc.L is None:
            proc_std = np.broadcast_to(proc_std, (ids.size, n)).copy()
        if meas_std is not None and meas_std.shape[0] == 1 and meas.L is None:
            meas_std = np.broadcast_to(meas_std, (ids.size, ny)).copy()
        cfg = _Pass(ids=ids, total=total, injector=injector, proc=proc, proc_mode=mode, meas=meas,
                    seed=int(seed), keep=keep, y_cols=y_cols)
        out = _run(plant, model, scenario, cfg)

    t = np.arange(Tm) * (dt * ratio)
    units = getattr(model, "units", None) or {}

    def sig(key: str, names: list[str]) -> Signals | None:
        if key not in out:
            return None
        return Signals(t, out[key], names, [units.get(s, "") for s in names], check=False)

    return SimResult(
        y=sig("y", [plant.outputs[i] for i in y_cols]),  # type: ignore[arg-type]
        x=sig("x", plant.states),
        u=sig("u", plant.controls),
        run_ids=ids,
        seed=int(seed),
        dt=dt,
        sample_time=dt * ratio,
        method=method,
        process_std=proc_std,
        measurement_std=meas_std,
        nominal_ms=nominal,
    )
