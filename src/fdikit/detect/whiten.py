"""Pre-whitening of serially and cross-correlated residuals by a vector autoregression (VAR).

Real residuals are correlated in time (a filter's output is coloured noise) and across channels.
A test that multiplies per-sample likelihoods (:class:`~fdikit.detect.MHSSPT`) then counts each
sample as new evidence and becomes overconfident. :class:`VARWhitener` fits, on nominal data,

    z_k = x_k - mu,    z_k = A_1 z_{k-1} + ... + A_p z_{k-p} + e_k

by least squares (order ``p`` by the Bayesian information criterion up to ``max_order``) and
outputs the one-step prediction errors ``e_k``: under the nominal model they are serially
uncorrelated (their covariance across channels remains and is what a full-covariance density
models). A fault that shifts the mean by ``d`` shifts the innovations by ``(I - sum A_i) d`` once
the history holds it, so densities calibrated on whitened fault segments see the same law.
Pre-whitening is chosen over an effective-sample correction (raising each likelihood to the power
``1 / tau``) because it is exact for an autoregressive process: it leaves the evidence of each
sample its true weight and keeps the shape of the posterior, while tempering only rescales it.

Many channels and few nominal samples (a VAR(p) of C channels needs about ``10 (p C + 1)``):
the fit refuses, naming what it needs and the alternatives, or with ``reduce=True`` lowers the
order to what the samples carry (by BIC or AIC) and, when not even a full VAR(1) fits, fits one
autoregression per channel (``structure="diagonal"``; the cross-channel correlation is then left to
the innovation covariance, estimated with shrinkage by
:func:`~fdikit.detect.mhsspt.calibrate_segments`).

Samples before the history is full use ``mu`` for the missing past (zero centred history); the
first ``p`` outputs of a record are therefore transients.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..base.stage import ResidualProcessor
from ..errors import DataError
from ..signals import Signals

__all__ = ["VARWhitener"]


def _records(data, C: int | None = None) -> list[np.ndarray]:
    if isinstance(data, Signals):
        return [v for v in data.values]
    if isinstance(data, np.ndarray):
        a = np.asarray(data, float)
        if a.ndim == 1:
            a = a[:, None]
        if a.ndim == 2:
            return [a]
        if a.ndim == 3:
            return list(a)
        raise DataError(f"records must be (T, C) or (runs, T, C), got shape {a.shape}")
    return [np.asarray(r, float).reshape(len(r), -1) for r in data]


def _n_fit(recs, p: int) -> int:
    return sum(max(0, r.shape[0] - p) for r in recs)


def _need(p: int, C: int, structure: str) -> int:
    """Samples a VAR(p) needs: ten per coefficient of one equation (and the mean)."""
    return 10 * (p * (C if structure == "full" else 1) + 1)


def _enough(recs, p: int, C: int, structure: str) -> bool:
    return _n_fit(recs, p) >= _need(p, C, structure)


class VARWhitener(ResidualProcessor):
    """Innovations of a vector autoregression fitted to nominal residuals (pre-whitening).

    Parameters
    ----------
    inputs : sequence of str
        Residual channels, C of them.
    mean : array (C,)
        Nominal mean ``mu``.
    coefs : array (p, C, C)
        ``A_1 .. A_p`` (``p = 0``: only the mean is removed).

    Notes
    -----
    Outputs ``"<input>:w"`` per input: ``e_k = z_k - sum_i A_i z_{k-i}``, ``z = x - mu``.

    Examples
    --------
    >>> import numpy as np
    >>> from scipy.signal import lfilter
    >>> x = lfilter([1.0], [1.0, -0.9], np.random.default_rng(0).normal(size=(20_000, 1)), axis=0)
    >>> w = VARWhitener.fit(x, ["r"])
    >>> w.order, round(float(w.coefs[0, 0, 0]), 2)
    (1, 0.9)
    >>> e = w.run(Signals(np.arange(20_000.0), x, ["r"]))["r:w"][0]
    >>> abs(float(np.corrcoef(e[1:-1], e[2:])[0, 1])) < 0.03
    True
    """

    def __init__(self, inputs: Sequence[str], mean, coefs):
        self.input_names = [str(s) for s in inputs]
        C = len(self.input_names)
        if C == 0:
            raise DataError("VARWhitener needs at least one input channel")
        self.mean = np.broadcast_to(np.asarray(mean, float), (C,)).copy()
        A = np.asarray(coefs, float)
        if A.size == 0:
            A = np.zeros((0, C, C))
        if A.ndim != 3 or A.shape[1:] != (C, C):
            raise DataError(f"coefs must be (p, {C}, {C}), got shape {A.shape}")
        if not (np.all(np.isfinite(A)) and np.all(np.isfinite(self.mean))):
            raise DataError("VARWhitener mean and coefs must be finite")
        self.coefs = A
        self.order = A.shape[0]
        self.output_names = [f"{s}:w" for s in self.input_names]
        self.info: dict = {}
        self.reset(1)

    @classmethod
    def fit(cls, nominal, inputs: Sequence[str], *, order: int | None = None,
            max_order: int = 10, criterion: str = "bic", structure: str = "full",
            reduce: bool = False) -> VARWhitener:
        """Least-squares VAR fit to nominal records; ``order`` None: by ``criterion`` in ``0..max_order``.

        ``nominal``: a Signals (its ``inputs`` channels), an array (T, C) or (runs, T, C), or a list
        of (T_i, C) segments (independent records). ``criterion``: ``"bic"`` (default) or ``"aic"``.
        ``structure``: ``"full"`` (every channel's past predicts every channel: ``p C^2``
        coefficients, ``10 (p C + 1)`` samples needed) or ``"diagonal"`` (one autoregression per
        channel: ``p`` coefficients each, ``10 (p + 1)`` samples; the cross-channel correlation is
        left to the innovation covariance). A full VAR of ``max_order`` the samples cannot carry is
        refused with the samples it needs and the alternatives, unless ``reduce``: then the
        orders the samples carry compete (``max_order`` lowered), and a diagonal VAR is fitted
        when not even a full VAR(1) fits. ``info`` records the order, the structure, the
        criterion of each order, the innovation covariance and the samples used (and ``reduced``
        with the reason, when ``reduce`` lowered the order or the structure).
        """
        if isinstance(nominal, Signals):
            recs = [v for v in nominal.values[:, :, nominal.index(list(inputs))]]
        else:
            recs = _records(nominal)
        C = len(inputs)
        for i, r in enumerate(recs):
            if r.ndim != 2 or r.shape[1] != C:
                raise DataError(f"nominal record {i} has shape {r.shape}; expected (T, {C}) for "
                                f"{list(inputs)}")
            if not np.all(np.isfinite(r)):
                k, c = np.argwhere(~np.isfinite(r))[0]
                raise DataError(f"nominal record {i}: channel {inputs[c]!r} is not finite at sample {k}")
        if criterion not in ("bic", "aic"):
            raise DataError(f"criterion must be 'bic' or 'aic', got {criterion!r}")
        if structure not in ("full", "diagonal"):
            raise DataError(f"structure must be 'full' or 'diagonal', got {structure!r}")
        mu = np.concatenate(recs).mean(axis=0)
        orders = [int(order)] if order is not None else list(range(int(max_order) + 1))
        pmax = max(orders)
        reduced = None
        if not _enough(recs, pmax, C, structure):
            feasible = [p for p in range(pmax, -1, -1) if _enough(recs, p, C, structure)]
            p_full = next((p for p in range(pmax, -1, -1) if _enough(recs, p, C, "full")), -1)
            p_diag = next((p for p in range(pmax, -1, -1) if _enough(recs, p, C, "diagonal")), -1)
            if not reduce or (not feasible and p_diag < 0):
                n_fit = _n_fit(recs, pmax)
                need = _need(pmax, C, structure)
                alts = []
                if structure == "full" and p_full >= 0:
                    alts.append(f"order <= {p_full} (max_order={p_full})")
                if structure == "full" and p_diag >= 1:
                    alts.append(f"a diagonal VAR (structure='diagonal', order <= {p_diag})")
                if p_diag >= 0 or p_full >= 0:
                    alts.append("reduce=True (the orders the samples carry, by the information criterion; "
                                "design_mhsspt does this by default)")
                alts.append("shrinkage covariances of the whitened features (calibrate_segments(cov="
                            "'ledoit_wolf' or 'oas'))")
                raise DataError(f"{n_fit} nominal samples after the first {pmax} of each record are too few "
                                f"for a {'diagonal ' if structure == 'diagonal' else ''}"
                                f"VAR({pmax}) of {C} channels (need >= {need}); alternatives: "
                                + "; ".join(alts))
            top = feasible[0] if feasible else -1
            if structure == "full" and top < 1 and p_diag >= 1:  # a diagonal VAR beats mean removal
                reduced = (f"full VAR({pmax}) needs {_need(pmax, C, 'full')} samples: diagonal VAR, "
                           f"orders <= {p_diag}")
                structure, top = "diagonal", p_diag
            else:
                reduced = (f"{structure} VAR({pmax}) needs {_need(pmax, C, structure)} samples: "
                           f"orders <= {top}")
            orders = [p for p in orders if p <= top] or [top]
            pmax = max(orders)
        # the same samples (k >= pmax in every record) for every order, so the criteria compare
        Y = np.concatenate([r[pmax:] - mu for r in recs])
        lags = [np.concatenate([r[pmax - i : r.shape[0] - i] - mu for r in recs]) for i in range(1, pmax + 1)]
        best, ic = None, {}
        for p in orders:
            if p == 0:
                A = np.zeros((0, C, C))
                E = Y
            elif structure == "diagonal":
                A = np.zeros((p, C, C))
                E = np.empty_like(Y)
                for c in range(C):
                    X = np.stack([lag[:, c] for lag in lags[:p]], axis=1)  # (n, p)
                    b, *_ = np.linalg.lstsq(X, Y[:, c], rcond=None)
                    A[:, c, c] = b
                    E[:, c] = Y[:, c] - X @ b
            else:
                X = np.concatenate(lags[:p], axis=1)  # (n, p C)
                B, *_ = np.linalg.lstsq(X, Y, rcond=None)  # (p C, C)
                A = B.T.reshape(C, p, C).transpose(1, 0, 2)
                E = Y - X @ B
            S = E.T @ E / E.shape[0]
            sign, logdet = np.linalg.slogdet(S)
            if sign <= 0:
                raise DataError(f"innovation covariance of the VAR({p}) is singular (channels {list(inputs)} "
                                f"linearly dependent?)")
            pen = np.log(E.shape[0]) if criterion == "bic" else 2.0
            # the penalty per coefficient times p C C (full) or p C (diagonal), in the order of operations
            # of the former BIC (bitwise the same values)
            b = float(E.shape[0] * logdet + (pen * p * C * C if structure == "full" else pen * p * C))
            ic[p] = b
            if best is None or b < best[0]:
                best = (b, p, A, S)
        w = cls(inputs, mu, best[2])
        w.info = {"order": best[1], criterion: ic, "criterion": criterion, "structure": structure,
                  "innovation_cov": best[3], "samples": int(Y.shape[0])}
        if reduced is not None:
            w.info["reduced"] = reduced
        return w

    _state_attrs = ("_hist",)

    def to_dict(self) -> dict:
        """Configuration as plain data."""
        return {"inputs": list(self.input_names), "mean": self.mean.tolist(), "coefs": self.coefs.tolist()}

    @classmethod
    def from_dict(cls, d: dict) -> VARWhitener:
        C = len(d["inputs"])
        return cls(d["inputs"], d["mean"], np.asarray(d["coefs"], float).reshape(-1, C, C))

    def reset(self, runs: int = 1) -> None:
        # centred past samples, most recent first: (runs, p, C)
        self._hist = np.zeros((runs, self.order, len(self.input_names)))

    def whiten(self, x: np.ndarray) -> np.ndarray:
        """Innovations of ``x`` (runs, T, C) continuing from the current history (updated)."""
        x = np.asarray(x, float)
        if x.ndim != 3 or x.shape[2] != len(self.input_names):
            raise DataError(f"whitener input must be (runs, T, {len(self.input_names)}), got {x.shape}")
        if x.shape[0] != self._hist.shape[0]:
            raise DataError(f"sample has {x.shape[0]} runs; the whitener was reset for {self._hist.shape[0]}")
        bad = ~np.isfinite(x)
        if bad.any():
            run, k, c = np.argwhere(bad)[0]
            raise DataError(f"whitener input {self.input_names[c]!r} is not finite at sample {k} (run {run})")
        p, C = self.order, x.shape[2]
        z = x - self.mean
        T = z.shape[1]
        # past samples in time order: (runs, p + T, C), the history first (oldest first)
        full = np.concatenate([self._hist[:, ::-1], z], axis=1)
        e = z.copy()
        for i in range(1, p + 1):
            past = full[:, p - i : p - i + T]  # z_{k-i}
            Ai = self.coefs[i - 1]
            for j in range(C):
                for c in range(C):  # elementwise: the same operations for any T (batch == streaming)
                    a = Ai[j, c]
                    if a != 0.0:
                        e[:, :, j] -= a * past[:, :, c]
        if p:
            self._hist = full[:, -p:][:, ::-1].copy()
        return e

    def _step(self, r: np.ndarray) -> np.ndarray:
        return self.whiten(r[:, None, :])[:, 0]

    def run(self, signals: Signals) -> Signals:
        x = signals.values[:, :, signals.index(self.input_names)]
        self.reset(signals.runs)
        return Signals(signals.t, self.whiten(x), self.output_names, check=False)
