"""Residual banks for fault isolation: structured residuals (the dedicated and generalised observer schemes).

A bank is a set of linear residual generators, each decoupled from a chosen set of faults (and from
every disturbance of the model) and sensitive to the others, so that the pattern of residuals that
react -- the *fault signature* -- tells which fault occurred (Gertler's structured residuals; Varga's
``efdisyn`` in FaultDetectionTools.jl is the anchor: the synthesis returns the filter, its internal form
and an info record). :func:`design_residual_bank` designs each residual as an exact unknown input
observer (:func:`~fdikit.residuals.design_uio`) where the rank conditions allow, and as the optimal
approximate filter (:func:`~fdikit.residuals.design_optimal_fdf`) otherwise, and then checks the design
*exactly* through its internal form (:func:`~fdikit.residuals.internal_form`):

* the **fault signature** (faults x residuals, 0/1) from the transfer fault -> residual, with the gains
  behind every entry (:class:`FaultSignature`);
* a **sensitivity check**: every residual keeps a useful gain to every fault it must see, at DC and over
  the band that matters, against its own noise (steady-state residual covariance from the noise
  covariances); if not, a :class:`SensitivityWarning` (or :class:`~fdikit.errors.ConditionError` with
  ``on_weak="raise"``) names the residual, the fault and the gain;
* an **isolability report** (:meth:`ResidualBank.isolability`): which faults are detectable, which pairs
  are isolable, and why the others are not.

Default structure (``structure=None``), the rule:

1. the *dedicated* observer scheme (DOS): residual ``i`` is decoupled from every fault but fault ``i``
   (a diagonal signature; isolates even simultaneous faults), used when every one of its residuals can
   be built (the target still reaches the residual after the others are decoupled);
2. otherwise the *generalised* observer scheme (GOS): residual ``i`` is decoupled from fault ``i`` only
   and sees all the others (signature = ones minus identity: distinct rows for two or more faults); a
   GOS residual that cannot be built (decoupling that one fault leaves no residual) is skipped and
   reported in ``info["skipped"]`` with the reason.

Sensor faults are decoupled in output space (``sensor="output"`` of :func:`design_uio`: the residual
does not read that measurement), the classical construction of sensor-fault banks. The observer weights
come from the noise covariances (process ``Q``, measurement ``R``): a Kalman-type gain, which keeps the
residual's gain to slow faults. (The fixed ``Q = R = I`` default of :func:`design_uio` makes a
high-gain observer on a well-damped sampled plant: it tracks a bias within a few samples and the
residual's DC gain falls to a few per cent -- issue 15.)
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.linalg as sla

from ..errors import ConditionError, DataError, ModelError
from ..model.linear import LinearFaultModel
from ..model.reduction import frequency_response
from .fdf import (
    FaultDetectionFilter,
    FilterDesign,
    _complement_rows,
    _discrete,
    _orth,
    design_optimal_fdf,
    design_uio,
    fault_direction_split,
    internal_form,
    stack_designs,
)

__all__ = ["BankResidual", "FaultSignature", "IsolabilityReport", "ResidualBank", "SensitivityWarning",
           "check_sensitivity", "design_residual_bank"]


class SensitivityWarning(UserWarning):
    """A residual of a bank has too little gain to a fault it must see (see :func:`design_residual_bank`)."""


# ---------------------------------------------------------------------------------------------- records
@dataclass
class BankResidual:
    """One residual of a bank.

    Attributes
    ----------
    name : str
        Residual name; its channels are ``name`` (one channel) or ``"<name>:<k>"``.
    decoupled : list of str
        Faults (and disturbances) the residual is designed to be blind to.
    sensitive : list of str
        Faults it must see (every other fault of the bank).
    design : FilterDesign
        Implementation form (``info["method"]`` is ``"uio"`` or ``"optimal_fdf"``).
    noise_cov : ndarray (q, q)
        Steady-state covariance of the residual's channels under the design noise.
    """

    name: str
    decoupled: list[str]
    sensitive: list[str]
    design: FilterDesign
    noise_cov: np.ndarray

    @property
    def method(self) -> str:
        return str(self.design.info.get("method"))

    @property
    def channels(self) -> list[str]:
        return list(self.design.residual_names)


@dataclass
class FaultSignature:
    """Fault signature matrix of a bank, computed from its internal form, with the gains behind it.

    Attributes
    ----------
    faults : list of str
        Rows (``n_f``).
    residuals : list of str
        Columns (``n_r``).
    matrix : ndarray of int (n_f, n_r)
        1 where the fault reaches the residual (relative peak gain above ``zero_tol``), 0 where it is
        decoupled.
    gain_dc : ndarray (n_f, n_r)
        Residual response at DC to a unit constant fault: 2-norm over the residual's channels (residual
        units per fault unit).
    gain_band : ndarray (n_f, n_r)
        Largest such response over the band (``band`` of the design).
    relative : ndarray (n_f, n_r)
        Peak gain over ``[0, Nyquist]`` divided by the peak of the fault's effect on the raw
        measurements (dimensionless; the decoupling measure).
    snr_dc, snr_band : ndarray (n_f, n_r) or None
        Whitened response ``|Sigma^-1/2 G(f) e_j| * size_j`` (noise standard deviations for the stated
        fault size) at DC and its largest value over the band; None without noise.
    useful : ndarray of bool (n_f, n_r)
        Entries that pass the sensitivity check (``min_snr`` with noise, ``min_gain`` on the relative
        DC and band gains without).
    band : tuple of float
        The band (Hz).
    """

    faults: list[str]
    residuals: list[str]
    matrix: np.ndarray
    gain_dc: np.ndarray
    gain_band: np.ndarray
    relative: np.ndarray
    snr_dc: np.ndarray | None
    snr_band: np.ndarray | None
    useful: np.ndarray
    band: tuple[float, float]

    def to_text(self) -> str:
        """Readable table: the 0/1 entry with its DC gain (and DC SNR) per fault and residual."""
        w0 = max(5, *(len(f) for f in self.faults))
        cells = []
        for i in range(len(self.faults)):
            row = []
            for j in range(len(self.residuals)):
                s = f"{int(self.matrix[i, j])} ({self.gain_dc[i, j]:.3g}"
                if self.snr_dc is not None:
                    s += f", snr {self.snr_dc[i, j]:.3g}"
                s += ")" + ("" if self.useful[i, j] or not self.matrix[i, j] else " weak")
                row.append(s)
            cells.append(row)
        widths = [max(len(r), *(len(c[j]) for c in cells)) for j, r in enumerate(self.residuals)]
        lines = [f"Fault signature ({len(self.faults)} faults x {len(self.residuals)} residuals; "
                 f"entry (DC gain{', DC snr' if self.snr_dc is not None else ''}))",
                 "fault".ljust(w0) + "".join("  " + r.rjust(w) for r, w in zip(self.residuals, widths))]
        for f, c in zip(self.faults, cells):
            lines.append(f.ljust(w0) + "".join("  " + x.rjust(w) for x, w in zip(c, widths)))
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.to_text()


@dataclass
class IsolabilityReport:
    """What a bank can detect and isolate (single faults), and why not.

    Attributes
    ----------
    detectable : list of str
        Faults with a useful gain in at least one residual.
    weakly_detectable : dict str -> str
        Faults that reach some residual, but never with a useful gain, with the best gain.
    undetectable : list of str
        Faults that reach no residual.
    isolable : list of tuple of str
        Pairs told apart by at least one residual with a useful gain to one of them and none to the other.
    not_isolable : dict tuple -> str
        Other pairs, with the reason (``"equal signatures ..."``, ``"no gain ..."``, ``"differ only
        through weak gains ..."``).
    """

    detectable: list[str]
    weakly_detectable: dict[str, str]
    undetectable: list[str]
    isolable: list[tuple[str, str]]
    not_isolable: dict[tuple[str, str], str]

    @property
    def fully_isolable(self) -> bool:
        """Every fault detectable and every pair isolable."""
        return not self.not_isolable and not self.undetectable and not self.weakly_detectable

    def to_text(self) -> str:
        lines = [f"detectable: {', '.join(self.detectable) or '-'}"]
        for f, why in self.weakly_detectable.items():
            lines.append(f"weakly detectable: {f}: {why}")
        if self.undetectable:
            lines.append(f"undetectable (no residual sees them): {', '.join(self.undetectable)}")
        lines.append(f"isolable pairs: {len(self.isolable)}")
        for (a, b), why in self.not_isolable.items():
            lines.append(f"not isolable: {a} / {b}: {why}")
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.to_text()


# ---------------------------------------------------------------------------------------------- the bank
class ResidualBank:
    """A designed residual bank: residuals, signature, sensitivity check and isolability.

    Built by :func:`design_residual_bank`. Attributes: ``model`` (the discrete design model),
    ``faults``, ``residuals`` (list of :class:`BankResidual`), ``signature`` (:class:`FaultSignature`),
    ``weak`` (list of ``(residual, fault, message)`` that failed the sensitivity check), ``info``.
    """

    def __init__(self, model: LinearFaultModel, faults: list[str], residuals: list[BankResidual],
                 signature: FaultSignature, weak: list[tuple[str, str, str]], info: dict[str, Any]):
        self.model = model
        self.faults = faults
        self.residuals = residuals
        self.signature = signature
        self.weak = weak
        self.info = info

    @property
    def residual_names(self) -> list[str]:
        return [r.name for r in self.residuals]

    @property
    def design(self) -> FilterDesign:
        """All residuals fused into one filter (:func:`~fdikit.residuals.stack_designs`)."""
        d = stack_designs([r.design for r in self.residuals])
        d.info.update(method="residual_bank", residuals=self.residual_names)
        return d

    def generator(self) -> FaultDetectionFilter:
        """One residual generator for the whole bank, with the residuals' named channels."""
        return FaultDetectionFilter(self.design)

    def internal_form(self, model: LinearFaultModel | None = None) -> LinearFaultModel:
        """Transfer from every input group of ``model`` (default: the design model) to all channels."""
        return internal_form(self.design, self.model if model is None else model)

    def channels(self, residual: str) -> list[str]:
        """Channel names of one residual."""
        for r in self.residuals:
            if r.name == residual:
                return r.channels
        raise ModelError(f"unknown residual {residual!r}; residuals are {self.residual_names}")

    def isolability(self) -> IsolabilityReport:
        """Detectability of every fault and isolability of every pair (single faults).

        A fault is detectable when some residual has a useful gain to it (sensitivity check). Two faults
        are isolable when some residual has a useful gain to one and is decoupled (signature 0) from the
        other.
        """
        S, U = self.signature.matrix.astype(bool), self.signature.useful
        R, F = self.signature.residuals, self.faults
        best = self.signature.snr_dc if self.signature.snr_dc is not None else self.signature.relative
        what = "DC snr" if self.signature.snr_dc is not None else "relative gain"
        detectable, weak, undet = [], {}, []
        for i, f in enumerate(F):
            if U[i].any():
                detectable.append(f)
            elif S[i].any():
                j = int(np.argmax(np.where(S[i], best[i], -np.inf)))
                weak[f] = f"reaches {int(S[i].sum())} residual(s) but never usefully (best: {R[j]!r}, " \
                          f"{what} {best[i, j]:.3g})"
            else:
                undet.append(f)
        iso, not_iso = [], {}
        for a in range(len(F)):
            for b in range(a + 1, len(F)):
                pair = (F[a], F[b])
                sep = (U[a] & ~S[b]) | (U[b] & ~S[a])
                if sep.any():
                    iso.append(pair)
                elif not (U[a].any() or U[b].any()):
                    not_iso[pair] = "no gain: neither fault has a useful gain in any residual"
                elif np.array_equal(S[a], S[b]):
                    cols = [R[j] for j in np.flatnonzero(S[a])]
                    not_iso[pair] = f"equal signatures: both reach residuals {cols} and no other"
                else:
                    diff = [R[j] for j in np.flatnonzero(S[a] != S[b])]
                    not_iso[pair] = f"differ only through weak gains (residuals {diff} below the " \
                                    "sensitivity threshold)"
        return IsolabilityReport(detectable, weak, undet, iso, not_iso)

    def __repr__(self) -> str:
        kinds = [r.method for r in self.residuals]
        return (f"ResidualBank({len(self.residuals)} residuals {self.residual_names}, faults {self.faults}, "
                f"structure {self.info.get('structure_rule')!r}, methods {kinds}, "
                f"weak entries {len(self.weak)})")


# ---------------------------------------------------------------------------------------------- noise
def _cov(v: Any, k: int, what: str) -> np.ndarray:
    a = np.asarray(v, float)
    if a.ndim == 0:
        a = np.full(k, float(a))
    if a.ndim == 1:
        if a.size != k:
            raise DataError(f"{what} variances need {k} entries, got {a.size}")
        a = np.diag(a)
    if a.shape != (k, k) or not np.all(np.isfinite(a)):
        raise DataError(f"{what} covariance must be finite with shape ({k}, {k}), got {a.shape}")
    a = 0.5 * (a + a.T)
    if np.min(np.linalg.eigvalsh(a)) < -1e-12 * max(1.0, float(np.abs(a).max())):
        raise DataError(f"{what} covariance is not positive semi-definite")
    return a


def _noise_covariances(model: LinearFaultModel, md: LinearFaultModel, noise: Any
                       ) -> tuple[np.ndarray, np.ndarray, str]:
    """Per-sample process covariance Qd (n, n) and measurement covariance R (p, p) of the discrete model."""
    n, p = md.n_states, md.n_outputs
    if noise is None:
        Bw, Dw = md.B_of("w"), md.D_of("w")
        if Bw.shape[1] == 0 or not (np.any(Bw) or np.any(Dw)):
            return np.zeros((n, n)), np.zeros((p, p)), "none"
        # the model's noise group, unit white noise (discretised with the model when continuous)
        if np.any(Bw @ Dw.T):
            raise ModelError("the model's noise group drives states and outputs together (Bw Dw' != 0); "
                             "give noise={'process': Q, 'measurement': R} explicitly")
        return Bw @ Bw.T, Dw @ Dw.T, "model noise group w"
    if isinstance(noise, Mapping):
        proc, meas, mode = noise.get("process"), noise.get("measurement"), noise.get("process_mode")
        unknown = set(noise) - {"process", "measurement", "process_mode"}
        if unknown:
            raise DataError(f"noise keys {sorted(unknown)} unknown; use 'process', 'measurement', "
                            "'process_mode'")
    elif hasattr(noise, "measurement") and hasattr(noise, "process"):
        if getattr(noise, "process_snr_db", None) is not None or getattr(noise, "measurement_snr_db", None) \
                is not None:
            raise DataError("noise given as an SNR cannot be used for design: give covariances")
        proc, meas, mode = noise.process, noise.measurement, noise.process_mode
    else:
        raise DataError(f"noise must be None, a mapping or a fdikit.faults.Noise, got {type(noise).__name__}")
    R = np.zeros((p, p)) if meas is None else _cov(meas, p, "measurement noise")
    if proc is None:
        return np.zeros((n, n)), R, "given"
    Q = _cov(proc, n, "process noise")
    if model.is_discrete or mode == "increment":
        return Q, R, "given"
    dt = md.dt
    if mode == "psd":
        return Q * dt, R, "given"
    # "derivative" (default for continuous models): w held over each step, x += Gamma w
    _, G = _zoh(model.A, np.eye(n), dt)
    return G @ Q @ G.T, R, "given"


def _zoh(A: np.ndarray, B: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    n, m = A.shape[0], B.shape[1]
    M = np.zeros((n + m, n + m))
    M[:n, :n], M[:n, n:] = A * dt, B * dt
    E = sla.expm(M)
    return E[:n, :n], E[:n, n:]


def _noise_model(md: LinearFaultModel, Q: np.ndarray, R: np.ndarray) -> LinearFaultModel:
    """The discrete model with its noise group replaced by factors of Q and R (unit white inputs)."""
    def factor(M):
        w, V = np.linalg.eigh(M)
        keep = w > 1e-15 * max(1.0, float(w.max()) if w.size else 1.0)
        return V[:, keep] * np.sqrt(w[keep])

    Lq, Lr = factor(Q), factor(R)
    n, p = md.n_states, md.n_outputs
    Bw = np.hstack([Lq, np.zeros((n, Lr.shape[1]))])
    Dw = np.hstack([np.zeros((p, Lq.shape[1])), Lr])
    faults = [(f, *md.fault_direction(f)) for f in md.fault_names]
    return LinearFaultModel(md.A, md.B, md.C, md.D, dt=md.dt, states=md.states, inputs=md.inputs,
                            outputs=md.outputs, Bd=md.B_of("d"), Dd=md.D_of("d"),
                            disturbances=md.input_names("d"), Bw=Bw, Dw=Dw,
                            noises=[f"w{i}" for i in range(Bw.shape[1])], faults=faults, name=md.name)


# ---------------------------------------------------------------------------------------------- gains
def _stationary_cov(A: np.ndarray, Bw: np.ndarray, C: np.ndarray, Dw: np.ndarray) -> np.ndarray:
    """Stationary covariance of ``r = C x + Dw w``, ``x+ = A x + Bw w`` (unit white ``w``).

    The internal form of a residual holds the plant's states too; a plant with a pole on the unit
    circle (an integrator) makes the full Lyapunov equation singular although the residual, which
    depends on the stable error dynamics only, has a finite covariance. Those modes are then
    removed first (minimal realisation of ``w -> r``, python-control ``minreal``)."""
    if not A.shape[0]:
        return Dw @ Dw.T
    try:
        if np.max(np.abs(np.linalg.eigvals(A))) < 1 - 1e-12:
            X = sla.solve_discrete_lyapunov(A, Bw @ Bw.T)
            return C @ X @ C.T + Dw @ Dw.T
    except (np.linalg.LinAlgError, ValueError):
        pass
    import control

    sys = control.minreal(control.ss(A, Bw, C, Dw, True), verbose=False)
    Am, Bm, Cm = np.asarray(sys.A), np.asarray(sys.B), np.asarray(sys.C)
    if Am.size and np.max(np.abs(np.linalg.eigvals(Am))) >= 1 - 1e-12:
        raise ModelError("the residual's noise response has a mode on or outside the unit circle: its "
                         "covariance is unbounded (an unstable or marginally stable error dynamics)")
    X = sla.solve_discrete_lyapunov(Am, Bm @ Bm.T) if Am.size else np.zeros((0, 0))
    return Cm @ X @ Cm.T + Dw @ Dw.T


def _fresp(model: LinearFaultModel, freqs: Any, group: str) -> np.ndarray:
    """:func:`~fdikit.model.reduction.frequency_response`, with "DC" taken a hair above 0 Hz (1e-7 of
    the Nyquist frequency) for a model with a pole at DC (an integrator: a motor's angle, a tank's
    level), whose response at exactly 0 Hz is unbounded."""
    f = np.atleast_1d(np.asarray(freqs, float))
    try:
        with np.errstate(all="ignore"):
            G = frequency_response(model, f, group)
        if np.all(np.isfinite(G)):
            return G
    except np.linalg.LinAlgError:
        pass
    nyq = 0.5 / model.dt if model.dt else 1.0
    return frequency_response(model, np.where(f <= 0, 1e-7 * nyq, f), group)


class _Context:
    """Frequency grids, the noise model and the faults' effect on the measurements, shared by the checks."""

    def __init__(self, md: LinearFaultModel, faults: list[str], Q: np.ndarray, R: np.ndarray,
                 band: tuple[float, float], sizes: np.ndarray):
        self.md, self.faults, self.sizes = md, faults, sizes
        self.has_noise = bool(np.any(Q) or np.any(R))
        self.noisy = _noise_model(md, Q, R) if self.has_noise else md
        nyq = 0.5 / md.dt
        self.band = band
        self.grid = np.unique(np.concatenate([list(band), np.linspace(band[0], band[1], 33)]))
        self.full = np.unique(np.concatenate([[0.0], np.geomspace(nyq * 1e-4, nyq, 120), self.grid]))
        self.fidx = [md.fault_names.index(f) for f in faults]
        Gy = _fresp(md, self.full, "f")[:, :, self.fidx]
        self.peak_y = np.linalg.norm(Gy, axis=1).max(axis=0)                         # (nf,)
        self.y_dc = np.linalg.norm(_fresp(md, [0.0], "f")[0][:, self.fidx], axis=0)
        self.y_band = np.linalg.norm(_fresp(md, self.grid, "f")[:, :, self.fidx], axis=1)

    def gains(self, d: FilterDesign) -> dict[str, np.ndarray]:
        """Gains of one residual to every fault, from its internal form against the noise model."""
        M = internal_form(d, self.noisy)
        fidx = self.fidx
        Gf = _fresp(M, self.full, "f")[:, :, fidx]                      # (F, q, nf)
        Gb = _fresp(M, self.grid, "f")[:, :, fidx]
        G0 = _fresp(M, [0.0], "f")[0][:, fidx]                          # (q, nf)
        q = len(d.residual_names)
        cov = np.zeros((q, q))
        if self.has_noise:
            Bw, Dw = M.B_of("w"), M.D_of("w")
            cov = _stationary_cov(M.A, Bw, M.C, Dw)
            cov = 0.5 * (cov + cov.T)
        band_abs = np.linalg.norm(Gb, axis=1)                                        # (F, nf)
        out = {"cov": cov, "gain_dc": np.linalg.norm(G0, axis=0), "gain_band_min": band_abs.min(axis=0),
               "relative": np.linalg.norm(Gf, axis=1).max(axis=0) / np.maximum(self.peak_y, 1e-300),
               "relative_dc": np.linalg.norm(G0, axis=0) / np.maximum(self.y_dc, 1e-300),
               "gain_band_max": band_abs.max(axis=0),
               "relative_band": (band_abs / np.maximum(self.y_band, 1e-300)).max(axis=0)}
        W = _whiten(cov) if self.has_noise else None
        if W is not None:
            out["snr_dc"] = np.linalg.norm(W @ G0, axis=0) * self.sizes
            out["snr_band"] = np.linalg.norm(W @ Gb, axis=1).max(axis=0) * self.sizes
        elif self.has_noise:
            out["snr_dc"] = np.zeros(len(fidx))
            out["snr_band"] = np.zeros(len(fidx))
        return out

    def verdict(self, rname: str, method: str, g: dict, i: int, min_snr: float, min_gain: float
                ) -> tuple[bool, str]:
        """Sensitivity check of residual ``rname`` to fault ``i``: (passes, message naming the numbers)."""
        f, size = self.faults[i], self.sizes[i]
        f_lo, f_hi = self.band
        rdc, rb = g["relative_dc"][i], g["relative_band"][i]
        head = (f"residual {rname!r} ({method}) barely sees fault {f!r}: DC gain {g['gain_dc'][i]:.3g} "
                f"per unit fault ({rdc:.3g} of the fault's effect on the measurements; at most {rb:.3g} in "
                f"the band {f_lo:g}-{f_hi:g} Hz)")
        if self.has_noise:
            std = np.sqrt(np.maximum(np.diag(g["cov"]), 0.0))
            snr, snrb = g["snr_dc"][i], g["snr_band"][i]
            ok = snr >= min_snr and snrb >= min_snr
            msg = (f"{head}; a fault of size {size:g} moves it by {snr:.3g} noise standard deviations at DC "
                   f"and at most {snrb:.3g} in the band (noise std {np.round(std, 6).tolist()}); "
                   f"needed: {min_snr:g}")
        else:
            ok = rdc >= min_gain and rb >= min_gain
            msg = f"{head}; needed: a fraction {min_gain:g} at DC and in the band (no noise given)"
        return bool(ok), msg


def check_sensitivity(design: Any, model: LinearFaultModel, faults: Sequence[str] | str, *,
                      noise: Any = None, band: tuple[float, float] | None = None,
                      fault_sizes: Mapping[str, float] | float | None = None,
                      min_snr: float = 3.0, min_gain: float = 0.1, on_weak: str = "warn",
                      name: str | None = None) -> list[tuple[str, str, str]]:
    """Design-time sensitivity check of any linear residual generator to the faults it must see.

    The check of :func:`design_residual_bank`, for one design: through the internal form
    (:func:`~fdikit.residuals.internal_form`) the residual's response to each fault of the stated size
    must reach ``min_snr`` standard deviations of its noise (the steady-state residual covariance under
    the noise covariances) at DC and at the best frequency of the band; without noise, its response
    must keep a fraction ``min_gain`` of the fault's effect on the measurements there.

    Parameters
    ----------
    design : FilterDesign or design with ``as_filter()``
    model : LinearFaultModel
    faults : str or sequence of str
        The faults the residual must see.
    noise, band, fault_sizes, min_snr, min_gain, on_weak
        As :func:`design_residual_bank`.
    name : str, optional
        Residual name in the messages (default: its first channel).

    Returns
    -------
    list of (residual, fault, message)
        The failed entries (empty when the residual is useful to every fault).

    Examples
    --------
    The default weights of :func:`~fdikit.residuals.design_uio` (``Q = R = I``) on a sampled DC motor:
    the observer tracks a current-sensor bias and keeps 3 % of it in the residual.

    >>> import numpy as np
    >>> from fdikit.model import LinearFaultModel
    >>> from fdikit.residuals import design_uio
    >>> m = LinearFaultModel([[-2.0, -0.02], [1.0, -10.0]], [[2.0], [0.0]], np.eye(2), inputs=["V"],
    ...                      outputs=["i", "w"], faults=["actuator:V", "sensor:i", "sensor:w"])
    >>> d = design_uio(m, ["sensor:i", "actuator:V"], ["sensor:w"], dt=0.01, sensor="output")
    >>> weak = check_sensitivity(d, m, ["sensor:i", "actuator:V"], on_weak="ignore", name="r_i")
    >>> [(r, f) for r, f, _ in weak]
    [('r_i', 'sensor:i'), ('r_i', 'actuator:V')]
    """
    if not isinstance(design, FilterDesign) and hasattr(design, "as_filter"):
        design = design.as_filter()
    md = _discrete(model, design.dt)
    faults = [faults] if isinstance(faults, str) else [str(f) for f in faults]
    bad = [f for f in faults if f not in md.fault_names]
    if bad:
        raise ModelError(f"faults {bad} are not declared on the model (faults: {md.fault_names})")
    if on_weak not in ("warn", "raise", "ignore"):
        raise ModelError(f"on_weak must be 'warn', 'raise' or 'ignore', got {on_weak!r}")
    Q, R, _ = _noise_covariances(model, md, noise)
    ctx = _Context(md, faults, Q, R, _band(band, md.dt), _sizes(fault_sizes, faults))
    g = ctx.gains(design)
    rname = name or design.residual_names[0]
    weak = []
    for i, f in enumerate(faults):
        ok, msg = ctx.verdict(rname, str(design.info.get("method", "design")), g, i, min_snr, min_gain)
        if not ok:
            weak.append((rname, f, msg))
    _report(weak, on_weak, {})
    return weak


def _band(band: Any, dt: float) -> tuple[float, float]:
    nyq = 0.5 / dt
    if band is None:
        return 0.0, 0.1 * nyq
    f_lo, f_hi = float(band[0]), float(band[1])
    if not (0 <= f_lo <= f_hi <= nyq * (1 + 1e-12)):
        raise ModelError(f"band must satisfy 0 <= f_lo <= f_hi <= Nyquist {nyq:g} Hz, got {band}")
    return f_lo, f_hi


def _sizes(fault_sizes: Any, faults: list[str]) -> np.ndarray:
    sizes = np.ones(len(faults))
    if fault_sizes is not None:
        if isinstance(fault_sizes, Mapping):
            unknown = [k for k in fault_sizes if k not in faults]
            if unknown:
                raise ModelError(f"fault_sizes names unknown faults {unknown}")
            sizes = np.array([float(fault_sizes.get(f, 1.0)) for f in faults])
        else:
            sizes = np.full(len(faults), float(fault_sizes))
        if not np.all((sizes > 0) & np.isfinite(sizes)):
            raise ModelError(f"fault sizes must be positive, got {sizes.tolist()}")
    return sizes


def _report(weak: list[tuple[str, str, str]], on_weak: str, details: dict) -> None:
    if not weak or on_weak == "ignore":
        return
    if on_weak == "raise":
        raise ConditionError("residual sensitivity", "; ".join(m for _, _, m in weak),
                             dict(details, weak=[(r, f) for r, f, _ in weak]))
    for _, _, m in weak:
        warnings.warn(m, SensitivityWarning, stacklevel=3)


# ---------------------------------------------------------------------------------------------- design
def _structure(structure: Any, faults: list[str]) -> list[tuple[str, list[str]]] | None:
    if structure is None:
        return None
    items = list(structure.items()) if isinstance(structure, Mapping) else \
        [(f"r{i + 1}", s) for i, s in enumerate(structure)]
    out = []
    for name, dec in items:
        dec = [dec] if isinstance(dec, str) else [str(s) for s in dec]
        bad = [s for s in dec if s not in faults]
        if bad:
            raise ModelError(f"residual {name!r} is to be decoupled from {bad}, which are not faults of the "
                             f"model {faults}")
        if len(set(dec)) == len(faults):
            raise ModelError(f"residual {name!r} is decoupled from every fault: it would see none")
        out.append((str(name), dec))
    names = [n for n, _ in out]
    if len(set(names)) != len(names):
        raise ModelError(f"duplicated residual names in the structure: {names}")
    return out


def _design_one(md: LinearFaultModel, target: list[str], nuisance: list[str], Q: np.ndarray, R: np.ndarray,
                method: str, gamma: float, name: str) -> FilterDesign:
    """Exact UIO with noise-based weights where it exists, else the optimal approximate filter."""
    n = md.n_states
    scale = max(float(np.trace(Q)) / max(n, 1), 1e-12)
    Qw = Q + 1e-6 * scale * np.eye(n)
    p = md.n_outputs
    rscale = float(np.trace(R)) / p if np.any(R) else 1.0
    Rv = R + 1e-6 * rscale * np.eye(p) if np.any(R) else np.eye(p)
    if not np.any(Q):          # no process noise known: a slow observer relative to the measurements
        Qw = 1e-3 * rscale * np.eye(n)
    uio_exc = None
    if method in ("auto", "uio"):
        Yd = fault_direction_split(md, nuisance, sensor="output")[1] if nuisance else np.zeros((p, 0))
        Pd = _complement_rows(_orth(Yd), p)
        try:
            return design_uio(md, target, nuisance, Q=Qw, R=Pd @ Rv @ Pd.T, sensor="output", name=name)
        except ConditionError as exc:
            if method == "uio" or exc.condition not in ("rank(CE) = rank(E)", "detectability of (C, A1)"):
                raise
            uio_exc = exc
    d = design_optimal_fdf(md, target, nuisance, gamma=gamma, Qw=Qw, V=Rv, sensor="output", name=name)
    if uio_exc is not None:
        d.info["uio_failed"] = str(uio_exc)
    return d


def _rename(design: FilterDesign, name: str) -> FilterDesign:
    q = len(design.residual_names)
    design.residual_names = [name] if q == 1 else [f"{name}:{k}" for k in range(q)]
    return design


def _whiten(cov: np.ndarray) -> np.ndarray | None:
    w, V = np.linalg.eigh(0.5 * (cov + cov.T))
    if w.size == 0 or w.max() <= 0:
        return None
    w = np.maximum(w, 1e-12 * w.max())
    return V @ np.diag(w ** -0.5) @ V.T


def design_residual_bank(
    model: LinearFaultModel,
    dt: float | None = None,
    structure: Any = None,
    *,
    faults: Sequence[str] | None = None,
    noise: Any = None,
    band: tuple[float, float] | None = None,
    fault_sizes: Mapping[str, float] | float | None = None,
    min_snr: float = 3.0,
    min_gain: float = 0.1,
    on_weak: str = "warn",
    method: str = "auto",
    gamma: float = 1e-6,
    zero_tol: float = 1e-6,
    name: str = "bank",
) -> ResidualBank:
    """Design a bank of structured residuals for fault isolation, and check it exactly.

    Parameters
    ----------
    model : LinearFaultModel
        Continuous (with ``dt``) or discrete. Its disturbances (group ``d``) are decoupled from every
        residual.
    dt : float, optional
        Sample time of the residuals (s); needed for a continuous model.
    structure : mapping or sequence, optional
        For each residual the faults it is decoupled from: ``{"r1": ["actuator:V"], ...}`` or a list of
        such lists (names ``r1, r2, ...``). Default: the rule of the module docstring (dedicated scheme
        if it exists, else the generalised one).
    faults : sequence of str, optional
        The faults of the bank (default: all faults declared on the model).
    noise : mapping or fdikit.faults.Noise, optional
        Noise covariances: ``{"process": Q (n,) or (n, n), "measurement": R (p,) or (p, p)}`` as in
        :class:`~fdikit.faults.Noise` (continuous model: ``Q`` of the held process noise, converted with
        ``process_mode``; discrete: per-sample). Default: the model's noise group ``w`` (unit white).
        They set the observer weights and the residual's noise for the sensitivity check.
    band : (f_lo, f_hi), optional
        Band that matters (Hz). Default ``(0, 0.05 / dt)`` (a tenth of the Nyquist frequency).
    fault_sizes : float or mapping fault -> float, optional
        Smallest fault magnitude that must be seen (fault units; default 1).
    min_snr : float
        With noise: a residual's response to a fault of the stated size must reach ``min_snr`` standard
        deviations of its noise (whitened norm over its channels, steady-state residual covariance) at DC
        (a constant fault) and at the best frequency of the band (a fault with content in the band).
    min_gain : float
        Without noise: the residual's response relative to the fault's effect on the raw measurements
        must reach ``min_gain`` at DC and at the best frequency of the band.
    on_weak : {"warn", "raise", "ignore"}
        What a failed sensitivity check does: a :class:`SensitivityWarning`, a
        :class:`~fdikit.errors.ConditionError` (``"residual sensitivity"``), or nothing (the entries are
        still in ``bank.weak``).
    method : {"auto", "uio", "optimal"}
        ``"auto"``: exact UIO where ``rank(CE) = rank(E)`` and detectability hold, else the optimal
        approximate filter (``gamma``).
    gamma : float
        Nuisance weighting of the optimal filter.
    zero_tol : float
        Relative peak gain below which a signature entry is 0 (decoupled).
    name : str
        Bank name (``info``).

    Returns
    -------
    ResidualBank
        ``residuals``, ``signature`` (:class:`FaultSignature`), ``weak`` (failed checks),
        ``isolability()``, ``generator()``; ``info`` has ``structure_rule``, ``skipped`` residuals with
        reasons, ``noise_source``, ``band``, ``dc_only`` and the design conditions of every residual.

    Raises
    ------
    ConditionError
        ``"residual sensitivity"`` (``on_weak="raise"``), naming residual, fault and gain; ``"bank
        structure"`` when no residual of the requested structure can be built; design conditions of a
        residual the user asked for (:func:`design_uio`, :func:`design_optimal_fdf`).

    Examples
    --------
    A DC motor (current, speed; voltage input) with faults on the actuator and both sensors; the
    dedicated scheme does not exist (two outputs, three faults), so the generalised one is used:

    >>> import numpy as np
    >>> from fdikit.model import LinearFaultModel
    >>> m = LinearFaultModel([[-2.0, -0.02], [1.0, -10.0]], [[2.0], [0.0]], np.eye(2),
    ...                      inputs=["V"], outputs=["i", "w"],
    ...                      faults=["actuator:V", "sensor:i", "sensor:w"])
    >>> bank = design_residual_bank(m, dt=0.01, noise={"process": [1e-4, 1e-4], "measurement": [1e-4, 1e-4]},
    ...                             on_weak="ignore")
    >>> bank.info["structure_rule"], bank.signature.matrix.tolist()
    ('generalised', [[0, 1, 1], [1, 0, 1], [1, 1, 0]])
    >>> bank.isolability().fully_isolable
    True
    """
    md = _discrete(model, dt)
    all_faults = md.fault_names
    faults = list(all_faults) if faults is None else [str(f) for f in faults]
    bad = [f for f in faults if f not in all_faults]
    if bad:
        raise ModelError(f"faults {bad} are not declared on the model (faults: {all_faults})")
    if len(faults) < 1:
        raise ModelError("a residual bank needs at least one fault")
    if on_weak not in ("warn", "raise", "ignore"):
        raise ModelError(f"on_weak must be 'warn', 'raise' or 'ignore', got {on_weak!r}")
    if not (min_snr > 0 and min_gain > 0 and zero_tol > 0):
        raise ModelError(f"min_snr, min_gain and zero_tol must be > 0, got {min_snr}, {min_gain}, {zero_tol}")
    Q, R, noise_source = _noise_covariances(model, md, noise)
    f_lo, f_hi = _band(band, md.dt)
    sizes = _sizes(fault_sizes, faults)
    # disturbances become nuisance faults decoupled from every residual
    dist = []
    work = md
    for k, dname in enumerate(md.input_names("d")):
        label = f"disturbance:{dname}"
        work = work.with_faults((label, md.B_of("d")[:, k], md.D_of("d")[:, k]))
        dist.append(label)
    skipped: dict[str, str] = {}
    designs: list[tuple[str, list[str], FilterDesign]] = []

    def build(rname, dec):
        target = [f for f in faults if f not in dec]
        return _rename(_design_one(work, target, list(dec) + dist, Q, R, method, gamma, rname), rname)

    struct = _structure(structure, faults)
    if struct is not None:
        rule = "given"
        for rname, dec in struct:
            designs.append((rname, dec, build(rname, dec)))
    else:
        rule = "dedicated"
        if len(faults) > 1:
            try:
                for f in faults:
                    dec = [g for g in faults if g != f]
                    designs.append((f"r[{f}]", dec, build(f"r[{f}]", dec)))
            except ConditionError as exc:
                skipped["dedicated scheme"] = f"residual seeing only {f!r}: {exc}"
                designs, rule = [], "generalised"
        else:
            designs.append((f"r[{faults[0]}]", [], build(f"r[{faults[0]}]", [])))
        if rule == "generalised":
            for f in faults:
                rname = f"r[~{f}]"
                try:
                    designs.append((rname, [f], build(rname, [f])))
                except ConditionError as exc:
                    skipped[rname] = str(exc)
    if not designs:
        raise ConditionError("bank structure", f"no residual of the {rule} scheme can be built for faults "
                             f"{faults}: {skipped}", {"skipped": skipped})
    # ------------------------------------------------------------------ exact check through the internal form
    ctx = _Context(md, faults, Q, R, (f_lo, f_hi), sizes)
    nr, nf = len(designs), len(faults)
    S = np.zeros((nf, nr), int)
    gdc, gband, rel = np.zeros((nf, nr)), np.zeros((nf, nr)), np.zeros((nf, nr))
    sdc = np.zeros((nf, nr)) if ctx.has_noise else None
    sband = np.zeros((nf, nr)) if ctx.has_noise else None
    residuals: list[BankResidual] = []
    weak: list[tuple[str, str, str]] = []
    useful = np.zeros((nf, nr), bool)
    for j, (rname, dec, d) in enumerate(designs):
        g = ctx.gains(d)
        S[:, j] = g["relative"] > zero_tol
        gdc[:, j], gband[:, j], rel[:, j] = g["gain_dc"], g["gain_band_max"], g["relative"]
        if ctx.has_noise:
            sdc[:, j], sband[:, j] = g["snr_dc"], g["snr_band"]
        r = BankResidual(rname, list(dec), [f for f in faults if f not in dec], d, g["cov"])
        residuals.append(r)
        for i, f in enumerate(faults):
            if f in r.decoupled:
                continue
            ok, msg = ctx.verdict(r.name, r.method, g, i, min_snr, min_gain)
            useful[i, j] = bool(ok and S[i, j])
            if not useful[i, j]:
                weak.append((r.name, f, msg))
    has_noise = ctx.has_noise
    sig = FaultSignature(list(faults), [r.name for r in residuals], S, gdc, gband, rel, sdc, sband, useful,
                         (f_lo, f_hi))
    # decoupling that the design promised but the internal form does not show
    leaks = [(r.name, f, float(rel[faults.index(f), j])) for j, r in enumerate(residuals)
             for f in r.decoupled if S[faults.index(f), j]]
    info = {"name": name, "structure_rule": rule, "skipped": skipped, "noise_source": noise_source,
            "band": (f_lo, f_hi), "min_snr": min_snr if has_noise else None,
            "min_gain": None if has_noise else min_gain, "fault_sizes": dict(zip(faults, sizes.tolist())),
            "disturbances_decoupled": dist, "decoupling_leaks": leaks,
            "residual_info": {r.name: r.design.info for r in residuals}}
    bank = ResidualBank(md, list(faults), residuals, sig, weak, info)
    _report(weak, on_weak, {"signature": S.tolist(), "gain_dc": gdc.tolist(),
                            "snr_dc": None if sdc is None else sdc.tolist()})
    return bank
