"""The SMO reconstructor at run time: :class:`SlidingModeReconstructor` (plain matrices, batch
and streaming on one compiled kernel) and :func:`integrate_observers`.

It integrates the observers with a fixed step equal to the sample time of the data: explicit
Euler for the linear part and an implicit (backward) step for the smoothed switching term (24),
which removes the numerical chattering of an explicit switched term; batch :meth:`run` and
streaming :meth:`step` call the same compiled kernel and agree to the last bit."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ...base.stage import ResidualGenerator
from ...errors import ConditionError, DataError, ModelError
from ...signals import Signals, check_finite
from .kernel import _kernel
from .noise_estimate import NOISE_BAND, NOISE_WARMUP, NOISE_WINDOW, _blend
from .validation import _mat, _pos

__all__ = ["TRANSIENT_HOLD", "TRANSIENT_LEVEL", "SlidingModeReconstructor", "integrate_observers"]

#: Default transient level of the status: a step whose injection moves more than this fraction of
#: ``rho`` away from the equivalent injection (``||Po (e+ - e)|| / h``) is not sliding.
TRANSIENT_LEVEL = 1e-3

#: Default hold of the transient test: samples the status stays "not sliding" after the last step
#: that moved the injection by more than ``transient_level * rho`` (issue 31: the move falls by
#: about 3.5x per sample after a jump and the estimate was 5.7 % off at the release).
TRANSIENT_HOLD = 3

@dataclass
class SlidingModeReconstructor(ResidualGenerator):
    """Runtime of the SMO fault reconstructor: plain matrices, fixed-step integration.

    Produced by :func:`design_reconstructor`. Inputs: the model's control channels ``u_names``
    and measured outputs ``y_names``, sampled every ``dt`` seconds (the integration step).
    Outputs: ``fhat:<fault>``, the reconstruction of each fault in the model's fault units, then
    the sliding status ``sliding_status`` (the worse of the two observers),
    ``sliding_status:primary`` and ``sliding_status:secondary``, per sample:
    ``0`` sliding (:data:`SLIDING`: the injection is inside its boundary layer, ``||nu|| <=
    level * rho``, so ``fhat`` is the equivalent injection), ``1`` not sliding
    (:data:`NOT_SLIDING`: reaching, the error is outside the layer but falling; or recovering:
    back in the layer for less than ``settle`` seconds after a loss) and ``2``
    saturated (:data:`SATURATED`: the injection is at its cap and the error is not falling: the
    gain is too small for the fault and ``fhat`` is clipped). A :class:`~fdikit.monitor.Decision`
    on ``sliding_status`` with ``level=1`` announces every loss of sliding as an event;
    :func:`sliding_episodes` lists them from a batch result.

    Attributes
    ----------
    cascade : bool
        Two observers (relative degree > 1) or one (A1 holds).
    primary : dict of ndarray
        ``A, B, C, Gl, Gn, rho, delta`` of the primary observer (canonical coordinates).
    secondary : dict of ndarray
        ``A, B, C, Gl, Gn, rho, delta`` of the secondary (or single) observer.
    Tv : ndarray (p, p)
        ``T^T Po^-1`` mapping the primary injection to ``v`` (23).
    Zsel : ndarray of int
        Components of ``v`` forming ``Z v1`` (27).
    Af : ndarray (r, r)
    Wf : ndarray (q, pbar)
        ``T2^T W Tbar^-1 Pobar^-1``: secondary injection -> fault (original fault coordinates).
    r : int
    dt : float
        Step (s).
    info : dict
        Case, conditions, ranks, pbar, L2 bound, H-infinity check, gains and the reconstructible
        range, noise design, solver records, timings (see :func:`design_reconstructor`).
    scheme : {"implicit", "explicit"}
        Treatment of the switched term in the Euler step (see :func:`integrate_observers`).
    level : float
        Boundary-layer level of the status: sliding while ``||nu|| <= level * rho`` (0 < level < 1).
    lpf_tau : float
        Time constant (s) of the first-order low-pass on ``fhat`` (0: none).
    transient_level : float
        Status: a step whose injection differs from the equivalent injection by more than
        ``transient_level * rho`` (``||Po (e+ - e)|| / h``: the error still moves inside the
        layer, as in the reaching after a fault jump) is not sliding (0: off).
    transient_hold : int
        Samples the status stays "not sliding" after the last such step (the tail of the
        reaching, still a few per cent off; 0: released at once).
    settle : float
        After a loss of sliding, the status stays "not sliding" until the error has stayed inside
        the boundary layer this long (s): the time the sliding motion needs to wash out what the
        loss left (:func:`design_reconstructor` sets three time constants of its slowest mode).
    clean_branch : SlidingModeReconstructor, optional
        A noise-aware design (``design_reconstructor(..., noise_std=...)``) also runs the default
        (noise-free) design on the same samples and uses it while the measured noise is small:
        per sample, the noise estimate of :func:`~fdikit.residuals.smo.estimate_noise_std`
        (``s_j`` on output ``j``) gives the ratio ``max_j s_j / noise_std_j``; below
        ``switch / band`` the output (estimates and status) is the clean branch's, above
        ``switch * band`` this reconstructor's own (the noise branch), log-linear blend between
        (status: the worse of the two). None: the noise branch alone.
    noise_switch : dict, optional
        With ``clean_branch``: ``noise_std`` (p), ``switch`` (the ratio at which the noise branch
        becomes the better one, found by simulation at design time), ``band``, ``window`` and
        ``warmup`` (samples; the noise branch is used until that many differences are averaged).
    """

    cascade: bool
    primary: dict
    secondary: dict
    Tv: np.ndarray
    Zsel: np.ndarray
    Af: np.ndarray
    Wf: np.ndarray
    r: int
    dt: float
    u_names: list[str]
    y_names: list[str]
    output_names: list[str]
    info: dict = field(default_factory=dict)
    details: dict = field(default_factory=dict, repr=False)
    scheme: str = "implicit"
    level: float = 0.9
    lpf_tau: float = 0.0
    settle: float = 0.0
    transient_level: float = TRANSIENT_LEVEL
    transient_hold: int = TRANSIENT_HOLD
    clean_branch: SlidingModeReconstructor | None = field(default=None, repr=False)
    noise_switch: dict | None = None

    STATUS_NAMES = ("sliding_status", "sliding_status:primary", "sliding_status:secondary")

    def __post_init__(self):
        if self.scheme not in ("implicit", "explicit"):
            raise ModelError(f"scheme must be 'implicit' or 'explicit', got {self.scheme!r}")
        self.dt = _pos(self.dt, "dt")
        self.level = _pos(self.level, "level")
        if not self.level < 1.0:
            raise DataError(f"level must be in (0, 1), got {self.level}")
        self.lpf_tau = _pos(self.lpf_tau, "lpf_tau", allow_zero=True)
        self.settle = _pos(self.settle, "settle", allow_zero=True)
        self.transient_level = _pos(self.transient_level, "transient_level", allow_zero=True)
        hold = self.transient_hold
        if isinstance(hold, bool) or not isinstance(hold, (int, np.integer)) or hold < 0:
            raise DataError(f"transient_hold must be an integer >= 0 (samples), got {hold!r}")
        self.transient_hold = int(hold)
        self.u_names, self.y_names = list(self.u_names), list(self.y_names)
        m, py = len(self.u_names), len(self.y_names)
        for key, d in (("primary", self.primary), ("secondary", self.secondary)):
            d["rho"] = _pos(d["rho"], "rho" if key == "primary" else "rho2")
            d["delta"] = _pos(d["delta"], "delta" if key == "primary" else "delta2")
            A = _mat(d["A"], (None, None), f"{key} A")
            n = A.shape[0]
            if A.shape != (n, n):
                raise DataError(f"{key} A must be square, got {A.shape}")
            C = _mat(d["C"], (None, n), f"{key} C")
            pk = C.shape[0]
            d["A"], d["C"] = np.ascontiguousarray(A), np.ascontiguousarray(C)
            d["B"] = np.ascontiguousarray(_mat(d["B"], (n, m), f"{key} B"))
            d["Gl"] = np.ascontiguousarray(_mat(d["Gl"], (n, pk), f"{key} Gl"))
            d["Gn"] = np.ascontiguousarray(_mat(d["Gn"], (n, pk), f"{key} Gn"))
        n1, p1 = self.primary["C"].shape[1], self.primary["C"].shape[0]
        n2, p2 = self.secondary["C"].shape[1], self.secondary["C"].shape[0]
        self.r = int(self.r)
        self.Zsel = np.ascontiguousarray(np.asarray(self.Zsel, dtype=np.int64).reshape(-1))
        if self.cascade:
            if p1 != py:
                raise DataError(f"the primary observer has {p1} outputs but y_names lists {py}")
            self.Tv = np.ascontiguousarray(_mat(self.Tv, (p1, p1), "Tv"))
            if not 0 <= self.r <= min(p1, p2) or self.Zsel.size != p2 - self.r:
                raise DataError(f"r = {self.r} and {self.Zsel.size} Zsel entries do not fit a secondary "
                                f"observer with {p2} outputs and a primary with {p1}")
            if self.Zsel.size and (self.Zsel.min() < 0 or self.Zsel.max() >= p1):
                raise DataError(f"Zsel must index the {p1} primary injections, got {self.Zsel.tolist()}")
            self.Af = np.ascontiguousarray(_mat(self.Af, (self.r, self.r), "Af"))
        else:
            if p2 != py:
                raise DataError(f"the observer has {p2} outputs but y_names lists {py}")
            if n1 or p1 or self.r or self.Zsel.size:
                raise DataError("a single-observer reconstructor has an empty primary observer, r = 0 "
                                "and no Zsel")
            self.Tv = np.zeros((0, 0))
            self.Af = np.zeros((0, 0))
        self.Wf = np.ascontiguousarray(_mat(self.Wf, (None, p2), "Wf"))
        q = self.Wf.shape[0]
        names = list(self.output_names)
        if len(names) == q:
            names += list(self.STATUS_NAMES)
        if len(names) != q + 3 or tuple(names[q:]) != self.STATUS_NAMES:
            raise DataError(f"output_names must list the {q} fault reconstructions (then the status "
                            f"channels {list(self.STATUS_NAMES)}), got {list(self.output_names)}")
        self.output_names = names
        self.output_units = None
        self._state: dict[str, np.ndarray] | None = None
        for d in (self.primary, self.secondary):
            C, Gn = d["C"], d["Gn"]
            if C.size:
                S = 0.5 * (C @ Gn + (C @ Gn).T)
                mu, V = np.linalg.eigh(S)
                if mu.min() <= 0:
                    raise ConditionError("LMI", f"C Gn is not positive definite (eigenvalues {mu})")
                d["SV"], d["Smu"] = np.ascontiguousarray(V), mu
            else:
                d["SV"], d["Smu"] = np.zeros((0, 0)), np.zeros(0)
        self._dims = (n1, p1, n2, p2)
        self._check_branch()

    def _check_branch(self) -> None:
        """Validate ``clean_branch`` / ``noise_switch`` (see the class docstring)."""
        cb, ns = self.clean_branch, self.noise_switch
        if cb is None and ns is None:
            return
        if not isinstance(cb, SlidingModeReconstructor) or not isinstance(ns, dict):
            raise DataError("clean_branch (a SlidingModeReconstructor) and noise_switch (a dict) go "
                            f"together, got {type(cb).__name__} and {type(ns).__name__}")
        if cb.clean_branch is not None:
            raise DataError("the clean branch of a reconstructor cannot have a clean branch itself")
        for key in ("dt", "u_names", "y_names", "output_names"):
            if getattr(cb, key) != getattr(self, key):
                raise DataError(f"clean_branch.{key} = {getattr(cb, key)!r} differs from "
                                f"{getattr(self, key)!r}")
        ns = {"band": NOISE_BAND, "window": NOISE_WINDOW, "warmup": NOISE_WARMUP, **ns}
        miss = [k for k in ("noise_std", "switch") if k not in ns]
        if miss:
            raise DataError(f"noise_switch lacks the keys {miss}")
        sig = np.asarray(ns["noise_std"], dtype=float).reshape(-1)
        if sig.size != len(self.y_names) or not np.all(np.isfinite(sig)) or sig.min() < 0 \
                or not sig.any():
            raise DataError(f"noise_switch['noise_std'] must be {len(self.y_names)} finite values >= 0, "
                            f"not all 0 (one per output {self.y_names}), got {ns['noise_std']!r}")
        ns["noise_std"] = sig.tolist()
        ns["switch"] = _pos(ns["switch"], "noise_switch['switch']")
        ns["band"] = _pos(ns["band"], "noise_switch['band']")
        if not ns["band"] >= 1.0:
            raise DataError(f"noise_switch['band'] must be >= 1, got {ns['band']}")
        for key in ("window", "warmup"):
            v = ns[key]
            if isinstance(v, bool) or not float(v).is_integer() or v < 1:
                raise DataError(f"noise_switch[{key!r}] must be an integer >= 1 (samples), got {v!r}")
            ns[key] = int(v)
        self.noise_switch = ns

    def noise_branch(self) -> SlidingModeReconstructor:
        """This reconstructor without its clean branch: the noise-aware design alone.

        Returns
        -------
        SlidingModeReconstructor
            Same observers, low-pass and status settings; ``clean_branch`` and ``noise_switch``
            None (``self`` when it has no clean branch).
        """
        if self.clean_branch is None:
            return self
        return replace(self, clean_branch=None, noise_switch=None)

    @property
    def fault_names(self) -> list[str]:
        """The reconstructed faults (``fhat:<fault>`` without the prefix)."""
        return [n.removeprefix("fhat:") for n in self.output_names[:self.Wf.shape[0]]]

    @property
    def n_faults(self) -> int:
        return int(self.Wf.shape[0])

    # ------------------------------------------------------------------ persistence
    _MATS = ("A", "B", "C", "Gl", "Gn")

    def to_dict(self) -> dict:
        """The runtime (plain gains and matrices) as a JSON-serialisable dict.

        The design-time ``details`` (canonical forms, LMI solutions) are not included; ``info``
        is kept with arrays converted to lists. :meth:`from_dict` rebuilds an identical runtime.
        """
        def obs(d):
            out = {k: np.asarray(d[k]).tolist() for k in self._MATS}
            out["shapes"] = {k: list(np.asarray(d[k]).shape) for k in self._MATS}
            out.update(rho=float(d["rho"]), delta=float(d["delta"]))
            return out

        def plain(v):
            if isinstance(v, dict):
                return {str(k): plain(x) for k, x in v.items()}
            if isinstance(v, list | tuple):
                return [plain(x) for x in v]
            if isinstance(v, np.ndarray):
                if v.dtype.kind == "c":
                    return {"real": v.real.tolist(), "imag": v.imag.tolist()}
                return v.tolist()
            if isinstance(v, (np.floating, np.integer, np.bool_)):
                return v.item()
            return v

        return {
            "kind": "fdikit.SlidingModeReconstructor", "version": 2, "cascade": self.cascade,
            "primary": obs(self.primary), "secondary": obs(self.secondary),
            "Tv": self.Tv.tolist(), "Tv_shape": list(self.Tv.shape), "Zsel": self.Zsel.tolist(),
            "Af": self.Af.tolist(), "Af_shape": list(self.Af.shape), "Wf": self.Wf.tolist(),
            "Wf_shape": list(self.Wf.shape),
            "r": self.r, "dt": self.dt, "u_names": self.u_names, "y_names": self.y_names,
            "output_names": self.output_names, "scheme": self.scheme, "level": self.level,
            "lpf_tau": self.lpf_tau, "settle": self.settle, "transient_level": self.transient_level,
            "transient_hold": self.transient_hold,
            "info": plain(self.info),
            **({} if self.clean_branch is None else {
                "clean_branch": {**self.clean_branch.to_dict(), "info": {}},
                "noise_switch": plain(self.noise_switch)}),
        }

    @classmethod
    def from_dict(cls, d: dict) -> SlidingModeReconstructor:
        """Rebuild a runtime saved by :meth:`to_dict` (also version 1, without the status channels).

        Examples
        --------
        >>> import json
        >>> from fdikit.systems import aircraft
        >>> from fdikit.residuals.smo import SlidingModeReconstructor, design_reconstructor
        >>> rec = design_reconstructor(aircraft.model(), hinf_check=False)
        >>> back = SlidingModeReconstructor.from_dict(json.loads(json.dumps(rec.to_dict())))
        >>> bool((back.Wf == rec.Wf).all()), back.output_names[0], back.output_names[1]
        (True, 'fhat:actuator:rudder_cmd', 'sliding_status')
        """
        if d.get("kind") != "fdikit.SlidingModeReconstructor":
            raise ModelError(f"not a saved SlidingModeReconstructor (kind = {d.get('kind')!r})")

        def obs(o):
            out = {k: np.asarray(o[k], float).reshape(o["shapes"][k]) for k in cls._MATS}
            out.update(rho=o["rho"], delta=o["delta"])
            return out

        names = list(d["output_names"])
        q = int(d["Wf_shape"][0]) if "Wf_shape" in d else len(names)
        return cls(
            cascade=bool(d["cascade"]), primary=obs(d["primary"]), secondary=obs(d["secondary"]),
            Tv=np.asarray(d["Tv"], float).reshape(d["Tv_shape"]),
            Zsel=np.asarray(d["Zsel"], dtype=np.int64),
            Af=np.asarray(d["Af"], float).reshape(d["Af_shape"]),
            Wf=np.asarray(d["Wf"], float).reshape(q, -1), r=int(d["r"]),
            dt=float(d["dt"]), u_names=list(d["u_names"]), y_names=list(d["y_names"]),
            output_names=names, info=dict(d.get("info", {})), scheme=d["scheme"],
            level=float(d.get("level", 0.9)), lpf_tau=float(d.get("lpf_tau", 0.0)),
            settle=float(d.get("settle", 0.0)),
            transient_level=float(d.get("transient_level", TRANSIENT_LEVEL)),
            transient_hold=int(d.get("transient_hold", 0)),
            clean_branch=cls.from_dict(d["clean_branch"]) if d.get("clean_branch") else None,
            noise_switch=dict(d["noise_switch"]) if d.get("noise_switch") else None)

    def error_transfer(self):
        """``G(s)`` of ng-tan-edwards-kuang eq. (40): ``xi`` -> reconstruction error ``f^ - f``.

        ``xi`` is the *input* of the uncertainty filter (3) (``xi~' = A_Omega xi~ + B_Omega xi``),
        not the model's disturbance ``xi~`` itself; gamma-bar (``info["l2_bound"]``) bounds this
        transfer's H-infinity norm.

        Returns
        -------
        control.StateSpace
            Inputs ``xi:<k>``, outputs ``fhat_err:<fault>`` in the model's fault coordinates
            (needs the design-time ``details``, i.e. a runtime made by :func:`design_reconstructor`).
        """
        import control

        if "G" not in self.details:
            raise ModelError("error_transfer needs the design details (not kept by to_dict/from_dict)")
        AG, BG, CG, DG = self.details["G"]
        T2 = self.details["lemma1"].T2
        return control.ss(AG, BG, T2.T @ CG, T2.T @ DG,
                          inputs=[f"xi:{k}" for k in range(BG.shape[1])],
                          outputs=[f"fhat_err:{n}" for n in self.fault_names])

    # ------------------------------------------------------------------ state
    _state_attrs = ("_state",)
    _checks_finite = True  # _advance names the channel, run and sample of a NaN itself

    def reset(self, runs: int = 1) -> None:
        """Zero observer states for ``runs`` parallel runs."""
        runs = int(runs)
        if runs < 1:
            raise DataError(f"runs must be >= 1, got {runs}")
        n1, p1, n2, p2 = self._dims
        self._state = {
            "x1": np.zeros((runs, n1)), "e1": np.zeros((runs, p1)),
            "x2": np.zeros((runs, n2)), "e2": np.zeros((runs, p2)),
            "vf": np.zeros((runs, self.r)), "started": np.zeros(runs, dtype=np.bool_),
            "flp": np.zeros((runs, self.n_faults)), "V1": np.zeros((runs, 2)),
            "V2": np.zeros((runs, 2)), "k": np.zeros(1, dtype=np.int64),
        }
        if self.clean_branch is not None:
            # the clean branch's state lives inside this one (one state to checkpoint), and the
            # noise estimator's: the last four samples, the samples seen, the log-mean of |d4|
            py = len(self.y_names)
            self.clean_branch.reset(runs)
            self._state.update(clean=self.clean_branch._state, ybuf=np.zeros((runs, 4, py)),
                               nseen=np.zeros((runs, 1)), lmean=np.zeros((runs, py)))

    def _check(self, U: np.ndarray, Y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Shapes and finiteness of a block of samples, before any state changes."""
        st = self._state
        U = np.asarray(U, dtype=float)
        Y = np.asarray(Y, dtype=float)
        m, py = len(self.u_names), len(self.y_names)
        if Y.ndim != 3 or Y.shape[2] != py:
            raise DataError(f"measurements must have shape (runs, T, {py}) for channels {self.y_names}, "
                            f"got {Y.shape}")
        if U.ndim != 3 or U.shape[:2] != Y.shape[:2] or U.shape[2] != m:
            raise DataError(f"inputs must have shape {(Y.shape[0], Y.shape[1], m)} for channels "
                            f"{self.u_names}, got {U.shape}")
        if st is None or st["x1"].shape[0] != Y.shape[0]:
            raise DataError(f"call reset({Y.shape[0]}) before stepping {Y.shape[0]} runs")
        k0 = int(st["k"][0])
        check_finite(U, self.u_names, what="reconstructor input", first_sample=k0)
        check_finite(Y, self.y_names, what="reconstructor measurement", first_sample=k0)
        return np.ascontiguousarray(U), np.ascontiguousarray(Y)

    def _advance(self, U: np.ndarray, Y: np.ndarray) -> np.ndarray:
        U, Y = self._check(U, Y)
        st = self._state
        q = self.n_faults
        out = np.zeros((Y.shape[0], Y.shape[1], q + 3))
        a_lp = float(np.exp(-self.dt / self.lpf_tau)) if self.lpf_tau > 0 else 0.0
        P, S = self.primary, self.secondary
        _kernel(float(self.dt), bool(self.cascade), P["A"], P["B"], P["C"], P["Gl"], P["Gn"],
                float(P["rho"]), float(P["delta"]), P["SV"], P["Smu"], self.Tv, int(self.r),
                self.Zsel, self.Af, S["A"], S["B"], S["C"], S["Gl"], S["Gn"], float(S["rho"]),
                float(S["delta"]), S["SV"], S["Smu"], self.Wf, U, Y,
                st["x1"], st["e1"], st["x2"], st["e2"], st["vf"], st["started"], out,
                self.scheme == "implicit", float(self.level), a_lp, st["flp"], st["V1"], st["V2"],
                float(np.ceil(self.settle / self.dt - 1e-9)) if self.settle > 0 else 0.0,
                float(self.transient_level), float(self.transient_hold))
        st["k"][0] += Y.shape[1]
        if self.clean_branch is None:
            return out
        cb, ns = self.clean_branch, self.noise_switch
        cb._state = st["clean"]  # a restored checkpoint replaces the dict
        out_c = cb._advance(U, Y)
        mixed = np.empty_like(out)
        ratio = np.empty(Y.shape[:2])
        _blend(Y, out, out_c, np.asarray(ns["noise_std"], float), float(ns["switch"]),
               float(ns["band"]), float(ns["window"]), float(ns["warmup"]), st["ybuf"], st["nseen"],
               st["lmean"], mixed, ratio)
        return mixed

    def _step(self, u: np.ndarray, y: np.ndarray) -> np.ndarray:
        return self._advance(u[:, None, :], y[:, None, :])[:, 0, :]

    def run(self, signals: Signals) -> Signals:
        """Reconstruction and sliding status over a whole record (all runs); same kernel as :meth:`step`.

        ``signals`` must be sampled uniformly at ``dt`` (relative tolerance 1e-6) and finite
        (a NaN or inf raises :class:`DataError` naming the channel, run and sample).
        """
        t = signals.t
        if t.size > 1:
            d = np.diff(t)
            bad = np.flatnonzero(np.abs(d - self.dt) > 1e-6 * self.dt)
            if bad.size:
                raise DataError(f"the reconstructor integrates with step dt = {self.dt} s but the "
                                f"record's sample {bad[0] + 1} follows after {d[bad[0]]} s")
        U, Y = self._inputs(signals)
        self.reset(signals.runs)
        out = self._advance(U, Y)
        return Signals(t, out, self.output_names, check=False)


def integrate_observers(rec: SlidingModeReconstructor, U: np.ndarray, Y: np.ndarray, *,
                        return_status: bool = False) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Run the reconstructor's observers over sampled inputs and outputs.

    The step is ``rec.dt``: explicit Euler for the linear part, implicit for the switched term.
    Implicit treatment of ``nu = -rho e / (||e|| + delta)`` keeps ``e_y`` on its discrete
    sliding surface instead of oscillating across it. An explicit step chatters with amplitude
    about ``h rho ||Po^-1||`` (1e-2 for the aircraft at ``h = 1e-5``, ``rho = 100``,
    ``Po ~ 0.1 I``, far above ``delta = 1e-5``); the chattering primary injection then drives the
    secondary observer off its sliding surface. Measured on the aircraft (15 s, nominal plant):
    RMS(f^ - f)/RMS(f) = 1.3e-5 (implicit, h = 1e-5), 1.1e-4 (implicit, h = 1e-4), 75
    (``scheme="explicit"`` at h = 1e-5 and at 1e-4).

    Parameters
    ----------
    rec : SlidingModeReconstructor
    U : ndarray (runs, T, m)
        Known inputs, ``m = len(rec.u_names)``.
    Y : ndarray (runs, T, p)
        Measurements, ``p = len(rec.y_names)``.
    return_status : bool
        Also return the sliding status codes.

    Returns
    -------
    ndarray (runs, T, q)
        Fault reconstructions.
    ndarray (runs, T, 3) of int8, with ``return_status``
        Combined, primary and secondary sliding status (:data:`SLIDING`, :data:`NOT_SLIDING`,
        :data:`SATURATED`).

    Raises
    ------
    DataError
        ``U`` or ``Y`` of the wrong shape (the compiled kernel never reads past an array), or a
        NaN/inf sample (named by channel, run and sample).
    """
    Y = np.asarray(Y, dtype=float)
    if Y.ndim != 3:
        raise DataError(f"Y must have shape (runs, T, {len(rec.y_names)}), got {Y.shape}")
    rec.reset(Y.shape[0])
    out = rec._advance(U, Y)
    q = rec.n_faults
    if return_status:
        return out[:, :, :q], out[:, :, q:].astype(np.int8)
    return out[:, :, :q]
