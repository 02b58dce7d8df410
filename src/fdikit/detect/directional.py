"""GLRT for an additive change along a known signature with an unknown amplitude.

The residual model under a fault is ``r_i = mu_0 + eta s_i + e_i`` with a *known* signature
sequence ``s_i`` (one value per residual channel and sample, e.g. the first-order response of an
observer residual to a parameter change, :class:`fdikit.residuals.ParameterSensitivity`), an
unknown amplitude ``eta`` and white Gaussian ``e_i`` of variance ``sigma^2`` per channel
(Basseville & Nikiforov, *Detection of Abrupt Changes*, 1993, Section 7.2: additive changes
with a known profile). Maximising the log-likelihood ratio over ``eta`` for a change starting
at sample ``j``::

    a_i = sum_c s_ic (r_ic - mu0_c) / sigma2_c          b_i = sum_c s_ic^2 / sigma2_c
    g_k(j) = (sum_{i=j..k} a_i)^2 / (2 sum_{i=j..k} b_i),   eta_hat = sum a_i / sum b_i

* ``W = None`` (anchored): the change is present from the first sample after :meth:`reset` --
  a parameter fault carried into the record -- and ``g_k = g_k(1)``; O(1) per sample. The
  evidence of a small parametric fault whose signature changes sign from one ABS cycle to the
  next accumulates over the whole stop, which no short window sees.
* ``W`` an integer: the change time is maximised over the last ``W`` samples, as in paper
  luo-et-al eq. (24); O(W) per sample with the same drift-free re-anchored running sums as
  :class:`~fdikit.detect.GLRT`. With one channel and ``s_i = 1`` this *is* eq. (24) (a test
  checks it).

Decoupling (``nuisance=``): when other faults have signatures ``s'_i, s''_i, ...`` that overlap
the tested one (for the ABS, the r3 signatures of K_f and R_w have a cosine of -0.94), their
amplitudes are left free as nuisance parameters and the statistic is the likelihood ratio for
``eta`` alone, ``g = eta_hat^2 / (2 [G^-1]_00)`` with ``G = sum_i S_i' Sigma^-1 S_i`` the
information matrix of all amplitudes (tested signature first) and ``eta_hat`` the first entry of
the joint least-squares estimate ``G^-1 sum_i S_i' Sigma^-1 (r_i - mu_0)``: a fault along a
nuisance signature leaves it at its no-fault distribution. This costs the part of the tested
signature that the nuisances can mimic (the information drops from ``G_00`` to
``1 / [G^-1]_00``).

``sum b_i`` is the Fisher information about ``eta`` in the window; where it does not exceed
``min_information`` (e.g. before any signature has appeared) the statistic and the estimate are
0. Under the no-fault hypothesis with white residuals, ``2 g_k`` is chi-square with one degree
of freedom at every fixed ``k`` for the anchored form; thresholds for coloured residuals come
from nominal Monte Carlo (:func:`~fdikit.detect.design_threshold`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numba import njit

from ..base.stage import ResidualProcessor
from ..errors import DataError
from ..signals import Signals, check_finite

__all__ = ["DirectionalGLRT", "directional_statistic"]


@njit(cache=True)
def _dglrt_batch(r, s, mu0, w, W, min_info, out_g, out_eta, A, B, pos, counts):  # pragma: no cover
    """r, s (runs, T, C) -> out_g, out_eta (runs, T).

    Anchored (``W == 0``): ``A[run, 0]``, ``B[run, 0]`` are the running sums. Windowed: ``A``,
    ``B`` (runs, 2W + 1) hold prefix sums relative to an anchor (``pos`` the newest), moved to
    the front every W samples as in the GLRT kernel, so no stored sum spans more than 2W samples.
    """
    R, T, C = r.shape
    top = 2 * W
    for run in range(R):
        Ar = A[run]
        Br = B[run]
        p = pos[run]
        count = counts[run]
        for k in range(T):
            a = 0.0
            b = 0.0
            for c in range(C):
                sc = s[run, k, c]
                a += sc * (r[run, k, c] - mu0[c]) * w[c]
                b += sc * sc * w[c]
            if W == 0:
                Ar[0] += a
                Br[0] += b
                if Br[0] > min_info:
                    out_g[run, k] = 0.5 * Ar[0] * Ar[0] / Br[0]
                    out_eta[run, k] = Ar[0] / Br[0]
                else:
                    out_g[run, k] = 0.0
                    out_eta[run, k] = 0.0
                continue
            if p == top:  # re-anchor: keep the last W + 1 prefix sums, the oldest becomes 0
                baseA = Ar[top - W]
                baseB = Br[top - W]
                for i in range(W + 1):
                    Ar[i] = Ar[top - W + i] - baseA
                    Br[i] = Br[top - W + i] - baseB
                p = W
            Ar[p + 1] = Ar[p] + a
            Br[p + 1] = Br[p] + b
            p += 1
            if count < W:
                count += 1
            best = 0.0
            eta = 0.0
            for L in range(1, count + 1):
                dA = Ar[p] - Ar[p - L]
                dB = Br[p] - Br[p - L]
                if dB > min_info:
                    v = 0.5 * dA * dA / dB
                    if v > best:
                        best = v
                        eta = dA / dB
            out_g[run, k] = best
            out_eta[run, k] = eta
        pos[run] = p
        counts[run] = count


@njit(cache=True)
def _solve_first(G, A, m, work, x):  # pragma: no cover - compiled
    """Cholesky of the m x m ``G``; returns (eta_0, [G^-1]_00) or (0, -1) if G is not positive definite.

    ``work`` (m, m + 2) scratch: L, then the solves of ``L y = A`` and ``L z = e_0``; ``x`` (m,)
    scratch for the back substitution (no allocation per call). A pivot
    below 1e-10 of the largest diagonal entry counts as singular (signatures that are linearly
    dependent over the window carry no separate information).
    """
    big = 0.0
    for j in range(m):
        big = max(big, G[j, j])
    if not big > 0.0:
        return 0.0, -1.0
    for j in range(m):
        d = G[j, j]
        for k in range(j):
            d -= work[j, k] * work[j, k]
        if not d > 1e-10 * big:
            return 0.0, -1.0
        ljj = np.sqrt(d)
        work[j, j] = ljj
        for i in range(j + 1, m):
            v = G[i, j]
            for k in range(j):
                v -= work[i, k] * work[j, k]
            work[i, j] = v / ljj
    # forward: y = L^-1 A, z = L^-1 e_0; then eta = L^-T y (first entry), [G^-1]_00 = |z|^2
    for i in range(m):
        y = A[i]
        z = 1.0 if i == 0 else 0.0
        for k in range(i):
            y -= work[i, k] * work[k, m]
            z -= work[i, k] * work[k, m + 1]
        work[i, m] = y / work[i, i]
        work[i, m + 1] = z / work[i, i]
    # backward for the first entry of L^-T y: solve L^T x = y, keep x_0
    for i in range(m - 1, -1, -1):
        v = work[i, m]
        for k in range(i + 1, m):
            v -= work[k, i] * x[k]
        x[i] = v / work[i, i]
    v00 = 0.0
    for i in range(m):
        v00 += work[i, m + 1] * work[i, m + 1]
    return x[0], v00


@njit(cache=True)
def _dglrt_multi(r, S, mu0, w, W, min_info, out_g, out_eta, A, G, pos, counts):  # pragma: no cover
    """Decoupled form: S (runs, T, C, m) with the tested signature at m-index 0.

    Anchored (``W == 0``): ``A[run, 0]`` (m,) and ``G[run, 0]`` (m, m) are the running sums;
    windowed: prefix sums (runs, 2W + 1, ...) re-anchored every W samples as in the GLRT.
    """
    R, T, C, m = S.shape
    top = 2 * W
    a = np.empty(m)
    g2 = np.empty((m, m))
    dA = np.empty(m)
    dG = np.empty((m, m))
    a0 = np.empty(m)
    g0 = np.empty((m, m))
    work = np.zeros((m, m + 2))
    xs = np.empty(m)
    for run in range(R):
        Ar = A[run]
        Gr = G[run]
        p = pos[run]
        count = counts[run]
        for k in range(T):
            a[:] = 0.0
            g2[:, :] = 0.0
            for c in range(C):
                e = (r[run, k, c] - mu0[c]) * w[c]
                for i in range(m):
                    si = S[run, k, c, i]
                    a[i] += si * e
                    for j in range(m):
                        g2[i, j] += si * S[run, k, c, j] * w[c]
            if W == 0:
                for i in range(m):
                    Ar[0, i] += a[i]
                    for j in range(m):
                        Gr[0, i, j] += g2[i, j]
                eta, v00 = _solve_first(Gr[0], Ar[0], m, work, xs)
                if v00 > 0.0 and 1.0 / v00 > min_info:
                    out_g[run, k] = 0.5 * eta * eta / v00
                    out_eta[run, k] = eta
                else:
                    out_g[run, k] = 0.0
                    out_eta[run, k] = 0.0
                continue
            if p == top:  # re-anchor: keep the last W + 1 prefix sums, the oldest becomes 0
                for i in range(m):
                    a0[i] = Ar[top - W, i]
                    for j in range(m):
                        g0[i, j] = Gr[top - W, i, j]
                for q in range(W + 1):
                    for i in range(m):
                        Ar[q, i] = Ar[top - W + q, i] - a0[i]
                        for j in range(m):
                            Gr[q, i, j] = Gr[top - W + q, i, j] - g0[i, j]
                p = W
            for i in range(m):
                Ar[p + 1, i] = Ar[p, i] + a[i]
                for j in range(m):
                    Gr[p + 1, i, j] = Gr[p, i, j] + g2[i, j]
            p += 1
            if count < W:
                count += 1
            best = 0.0
            best_eta = 0.0
            for L in range(1, count + 1):
                for i in range(m):
                    dA[i] = Ar[p, i] - Ar[p - L, i]
                    for j in range(m):
                        dG[i, j] = Gr[p, i, j] - Gr[p - L, i, j]
                eta, v00 = _solve_first(dG, dA, m, work, xs)
                if v00 > 0.0 and 1.0 / v00 > min_info:
                    v = 0.5 * eta * eta / v00
                    if v > best:
                        best = v
                        best_eta = eta
            out_g[run, k] = best
            out_eta[run, k] = best_eta
        pos[run] = p
        counts[run] = count


class DirectionalGLRT(ResidualProcessor):
    """GLRT for a change along a known signature with unknown amplitude (see the module docstring).

    Parameters
    ----------
    inputs : sequence of str
        Residual channels ``r_c``.
    signatures : sequence of str
        One signature channel ``s_c`` per residual channel (same order), read from the same
        signals (e.g. ``"sig:r3:I_w"`` of :class:`~fdikit.residuals.ParameterSensitivity`).
    mu0, sigma2 : float or sequence
        Nominal mean and variance of each residual channel.
    W : int or None
        ``None``: anchored at the first sample (the change present from the start, O(1) per
        sample); an integer >= 1: moving window over the candidate change times (O(W)).
    min_information : float
        The statistic is 0 where ``sum b_i`` (the information about ``eta``, in 1/eta^2; with
        nuisances ``1 / [G^-1]_00``) does not exceed this value (>= 0).
    nuisance : sequence of sequences of str
        Signatures of other faults to decouple from, each with one channel per residual channel
        (see the module docstring); default none.
    name : str, optional
        Prefix of the outputs (default: the first signature channel).

    Notes
    -----
    Outputs ``"<name>:dglrt"`` (the statistic ``g_k``) and ``"<name>:eta"`` (the amplitude
    estimate at the maximising change time; the relative parameter change when the signature
    is a :class:`~fdikit.residuals.ParameterSensitivity` channel).

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit import Signals
    >>> s = np.array([0.0, 1.0, -1.0, 2.0, -2.0, 1.0])
    >>> r = 0.1 * s                                  # a change of amplitude 0.1 along s
    >>> sig = Signals(np.arange(6.0), np.stack([r, s], -1), ["r", "s"])
    >>> out = DirectionalGLRT(["r"], ["s"], sigma2=0.01, name="f").run(sig)
    >>> # eta = 0.1 and g = eta^2 sum s^2 / (2 sigma^2) = 0.01 * 11 / 0.02
    >>> round(float(out["f:eta"][0, -1]), 6), round(float(out["f:dglrt"][0, -1]), 6)
    (0.1, 5.5)
    """

    def __init__(self, inputs: Sequence[str], signatures: Sequence[str], mu0=0.0, sigma2=1.0,
                 W: int | None = None, *, min_information: float = 0.0, name: str | None = None,
                 nuisance: Sequence[Sequence[str]] = ()):
        self.residual_names = [str(x) for x in inputs]
        self.signature_names = [str(x) for x in signatures]
        if isinstance(nuisance, str) or any(isinstance(n, str) for n in nuisance):
            raise DataError("nuisance must be a list of signature-channel lists, e.g. [['sig:r3:R_w']]")
        self.nuisance_names = [[str(x) for x in n] for n in nuisance]
        c = len(self.residual_names)
        if c == 0:
            raise DataError("DirectionalGLRT needs at least one residual channel")
        for sig in [self.signature_names, *self.nuisance_names]:
            if len(sig) != c:
                raise DataError(f"DirectionalGLRT: {c} residual channels {self.residual_names} need {c} "
                                f"signature channels, got {sig}")
        if W is not None and (int(W) != W or W < 1):
            raise DataError(f"DirectionalGLRT window W must be None (anchored) or an integer >= 1, got {W}")
        self.W = None if W is None else int(W)
        self.mu0 = np.broadcast_to(np.asarray(mu0, float), (c,)).copy()
        self.sigma2 = np.broadcast_to(np.asarray(sigma2, float), (c,)).copy()
        if not (np.all(np.isfinite(self.mu0)) and np.all(np.isfinite(self.sigma2))):
            raise DataError("DirectionalGLRT mu0 and sigma2 must be finite")
        if np.any(self.sigma2 <= 0):
            bad = self.residual_names[int(np.argmax(self.sigma2 <= 0))]
            raise DataError(f"DirectionalGLRT sigma2 must be positive; channel {bad!r} has "
                            f"{self.sigma2.min()}")
        if not (np.isfinite(min_information) and min_information >= 0):
            raise DataError(f"min_information must be finite and >= 0, got {min_information}")
        self.min_information = float(min_information)
        self.name = str(name) if name is not None else self.signature_names[0]
        self.input_names = self.residual_names + self.signature_names + [x for n in self.nuisance_names
                                                                        for x in n]
        if len(set(self.input_names)) != len(self.input_names):
            raise DataError(f"DirectionalGLRT: input channels repeat: {self.input_names}")
        self.output_names = [f"{self.name}:dglrt", f"{self.name}:eta"]
        self.reset(1)

    _state_attrs = ("_A", "_B", "_pos", "_counts", "_k")

    def to_dict(self) -> dict:
        """Configuration as plain data (a design artifact, :mod:`fdikit.base.artifacts`)."""
        return {"inputs": list(self.residual_names), "signatures": list(self.signature_names),
                "mu0": self.mu0.tolist(), "sigma2": self.sigma2.tolist(), "W": self.W,
                "min_information": self.min_information, "name": self.name,
                "nuisance": [list(n) for n in self.nuisance_names]}

    @classmethod
    def from_dict(cls, d: dict) -> DirectionalGLRT:
        return cls(d["inputs"], d["signatures"], d["mu0"], d["sigma2"], d["W"],
                   min_information=d.get("min_information", 0.0), name=d.get("name"),
                   nuisance=d.get("nuisance", ()))

    @property
    def n_directions(self) -> int:
        """1 + the number of nuisance signatures."""
        return 1 + len(self.nuisance_names)

    def reset(self, runs: int = 1) -> None:
        n = 1 if self.W is None else 2 * self.W + 1
        m = self.n_directions
        if m == 1:
            self._A = np.zeros((runs, n))
            self._B = np.zeros((runs, n))
        else:
            self._A = np.zeros((runs, n, m))
            self._B = np.zeros((runs, n, m, m))
        self._pos = np.zeros(runs, np.int64)
        self._counts = np.zeros(runs, np.int64)
        self._k = 0

    def _compute(self, r: np.ndarray, s: np.ndarray) -> np.ndarray:
        """r (runs, T, C) residuals, s (runs, T, C * m) signatures: tested first, then each nuisance."""
        R, T, C = r.shape
        g = np.empty((R, T))
        eta = np.empty((R, T))
        W = 0 if self.W is None else self.W
        m = self.n_directions
        if m == 1:
            _dglrt_batch(np.ascontiguousarray(r, float), np.ascontiguousarray(s, float), self.mu0,
                         1.0 / self.sigma2, W, self.min_information, g, eta,
                         self._A, self._B, self._pos, self._counts)
        else:
            S = np.ascontiguousarray(np.moveaxis(s.reshape(R, T, m, C), 2, 3), float)
            _dglrt_multi(np.ascontiguousarray(r, float), S, self.mu0, 1.0 / self.sigma2, W,
                         self.min_information, g, eta, self._A, self._B, self._pos, self._counts)
        return np.stack([g, eta], axis=-1)

    def _check(self, x: np.ndarray, k0: int) -> None:
        check_finite(x, self.input_names, what="DirectionalGLRT input", first_sample=k0)

    def _step(self, x: np.ndarray) -> np.ndarray:
        if x.shape[0] != self._A.shape[0]:
            raise DataError(f"sample has {x.shape[0]} runs; the test was reset for {self._A.shape[0]}")
        self._check(x[:, None, :], self._k)
        self._k += 1
        c = len(self.residual_names)
        return self._compute(x[:, None, :c], x[:, None, c:])[:, 0]

    def run(self, signals: Signals) -> Signals:
        x = signals.values[:, :, signals.index(self.input_names)]
        if self.W is not None and signals.n_samples < self.W:
            raise DataError(f"record of {signals.n_samples} samples is shorter than the window W = {self.W}")
        self._check(x, 0)
        self.reset(signals.runs)
        c = len(self.residual_names)
        out = self._compute(x[:, :, :c], x[:, :, c:])
        return Signals(signals.t, out, self.output_names, check=False)


def directional_statistic(r, s, mu0=0.0, sigma2=1.0, W: int | None = None, *,
                          min_information: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Statistic and amplitude estimate of :class:`DirectionalGLRT` for plain arrays.

    Parameters
    ----------
    r, s : array_like
        Residuals and signatures shaped (T,), (runs, T) or (runs, T, C).

    Returns
    -------
    g, eta : ndarray
        Shaped (T,) for 1-D input, else (runs, T).

    Examples
    --------
    >>> import numpy as np
    >>> g, eta = directional_statistic(np.full(8, 0.5), np.ones(8), sigma2=0.25, W=4)
    >>> float(g[-1]), float(eta[-1])   # eq. (24): W d^2 / (2 sigma^2) = 4 * 0.25 / 0.5
    (2.0, 0.5)
    """
    r = np.asarray(r, float)
    s = np.asarray(s, float)
    if r.shape != s.shape:
        raise DataError(f"residuals {r.shape} and signatures {s.shape} must have the same shape")
    one = r.ndim == 1
    if r.ndim == 1:
        r, s = r[None, :, None], s[None, :, None]
    elif r.ndim == 2:
        r, s = r[:, :, None], s[:, :, None]
    C = r.shape[2]
    names = [f"r{i}" for i in range(C)]
    sig = [f"s{i}" for i in range(C)]
    t = DirectionalGLRT(names, sig, mu0, sigma2, W, min_information=min_information)
    t.reset(r.shape[0])
    out = t._compute(r, s)
    g, eta = out[..., 0], out[..., 1]
    return (g[0], eta[0]) if one else (g, eta)
