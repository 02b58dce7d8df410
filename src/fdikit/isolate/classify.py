"""Isolation from labelled residual records: causal window features, a nominal gate designed for a
false-alarm target, and a cross-validated classifier among the faults.

Real residuals are correlated across channels and in time, and drift with the operating point; a
per-sample threshold per residual wastes most of their information (a D-matrix of binary tests
sees only which residual crossed its threshold, not by how much and in which combination). The
:class:`WindowedIsolator` uses all of it:

1. **features**: the causal moving average of every residual over the last ``window`` samples
   (``window`` = 1: the samples themselves). Averaging a constant fault over ``W`` samples of AR(1)
   noise with coefficient ``phi`` divides the noise variance by about ``W (1 - phi) / (1 + phi)``;
2. **nominal gate**: the Mahalanobis distance of the features from their nominal mean, in a
   *shrinkage* covariance of the nominal features (Oracle Approximating Shrinkage or Ledoit-Wolf,
   :mod:`sklearn.covariance`; optionally only its ``rank`` leading principal directions), against
   a threshold for the per-sample false-alarm probability ``pfa`` set on nominal data the mean and
   covariance did **not** see (time-blocked). ``calibration="interleaved"`` (default) cuts the
   nominal samples into alternate contiguous fit / calibration blocks (each at least 5
   autocorrelation times long, at most ``2 folds`` blocks; fit samples within a gap of
   ``max(window, tau)`` of a calibration block left out), so that both parts span the record's
   operating conditions; ``"holdout"`` fits on the first part and sets the threshold on the last
   ``holdout`` fraction; ``"crossfit"`` fits on all but one of ``folds`` contiguous folds,
   evaluates the left-out fold, and refits on everything (the refitted gate sees less estimation
   noise than the fold gates the threshold was set with, so its rate on new data is usually
   *below* the claim: measured 0.035-0.09 for a claim of 0.1 on white noise). The mean's condition
   regression is fitted on the fit part as well. The claim is then *checked*: the
   threshold set on all calibration blocks but one is applied to the block left out, and the
   held-out rate gets a moving-block bootstrap interval that accounts for serial correlation
   (:func:`fdikit.detect.tail.block_rate_ci`, :func:`~fdikit.detect.tail.block_length`). A design
   whose target lies outside that interval is refused (:class:`~fdikit.DataError`) unless
   ``accept_miscalibrated=True``; :attr:`WindowedIsolator.design_report_` holds claim and
   measurement side by side. Below the gate the sample is ``nominal``: the false-alarm rate is set
   by design, not by the classifier. (The former design -- the plain covariance and a bootstrap
   quantile on the samples it was fitted on -- claimed 0.096 and measured 0.49 on fresh white
   noise with 42 channels and 1 200 samples, and 100 % on held-out real residuals whose covariance
   had a condition number of 5e11.)
3. **isolation**: above the gate, a classifier trained on the fault samples only names the fault.
   The default (``"auto"``) chooses between linear discriminant analysis (window means of residuals
   in Gaussian noise are Gaussian with a common covariance, which is LDA's model) and a random
   forest (faults that are not mean shifts) by time-blocked cross-validation
   (:class:`~fdikit.isolate.svm.BlockedStratifiedKFold`) on the fault samples; any scikit-learn
   classifier can be given, with ``param_grid`` searched over the same time-blocked folds.
   Training samples within ``window`` of a label change are left out (their window mixes two
   classes). Trained on nominal samples only, the isolator is a novelty detector: above the gate
   it answers ``"unknown"``.

Operating conditions that move the nominal residuals (speed, load: measured signals) are given as
``condition`` (T, m): the nominal mean of the features is then regressed on their window means
(``mu(o) = mu_0 + B o``), and the gate and the classifier see the features less that mean.
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np

from ..errors import DataError

__all__ = ["WindowedIsolator", "moving_average"]


def moving_average(r: Any, window: int) -> np.ndarray:
    """Causal moving average over the last ``window`` samples of ``r`` (T, C) (shorter at the start).

    Examples
    --------
    >>> moving_average(np.array([[1.0], [3.0], [5.0], [7.0]]), 2).ravel().tolist()
    [1.0, 2.0, 4.0, 6.0]
    """
    r = np.asarray(r, dtype=float)
    if r.ndim == 1:
        r = r[:, None]
    if r.ndim != 2:
        raise DataError(f"residuals must be (T, channels), got shape {r.shape}")
    W = int(window)
    if W != window or W < 1:
        raise DataError(f"window must be an integer >= 1 sample, got {window}")
    c = np.cumsum(np.vstack([np.zeros((1, r.shape[1])), r]), axis=0)
    k = np.arange(1, r.shape[0] + 1)
    lo = np.maximum(k - W, 0)
    return (c[k] - c[lo]) / (k - lo)[:, None]


BLOCK_TAUS = 5  # the shortest fit / calibration block of the interleaved design, autocorrelation times
MIN_EFFECTIVE = 10  # effective samples a covariance fit or a rate check needs at the least
COVARIANCES = ("oas", "ledoit_wolf", "empirical")
CALIBRATIONS = ("interleaved", "holdout", "crossfit")
CLASSIFIERS = ("auto", "default", "lda", "forest")


class WindowedIsolator:
    """Window features, a nominal gate at a false-alarm target, and a classifier among the faults.

    Parameters
    ----------
    window : int
        Samples of the causal moving average (the detection delay is of this order).
    pfa : float
        Per-sample false-alarm probability the nominal gate is designed for, checked on held-out
        nominal data (see the module docstring and :attr:`design_report_`).
    classifier : "auto", "lda", "forest" or scikit-learn classifier
        Trained on the fault samples. ``"auto"`` (``"default"``): linear discriminant analysis or a
        random forest, whichever isolates better in time-blocked cross-validation; ``"lda"``,
        ``"forest"``: that one; an estimator: it (cloned), e.g.
        :func:`~fdikit.isolate.svm.cv_pipeline` for an RBF SVM.
    nominal : str
        The label of fault-free samples.
    max_train : int
        At most this many fault samples train the classifier (evenly spaced; an SVM's cost grows
        with the square of the samples).
    random_state : int
        Seed of the bootstrap and of the random forest.
    covariance : "oas", "ledoit_wolf" or "empirical"
        Estimator of the nominal covariance of the features: Oracle Approximating Shrinkage
        (default), Ledoit-Wolf shrinkage (:mod:`sklearn.covariance`), or the sample covariance
        (needs at least twice as many effective samples as features).
    rank : int, optional
        Use only the ``rank`` leading principal directions of the covariance in the gate (when the
        nominal samples are few for the number of features); default all.
    calibration : "interleaved", "holdout" or "crossfit"
        How the threshold is set on nominal data the mean and covariance did not see (see the
        module docstring): alternate contiguous fit / calibration blocks (default), the last
        ``holdout`` fraction of the nominal samples, or ``folds`` contiguous folds each evaluated
        by a fit on the others (then refitted on all: conservative).
    holdout : float
        Fraction of the nominal samples that set the threshold (``calibration="holdout"`` only).
    folds : int
        Contiguous folds of the threshold check, of ``crossfit``, and of the classifier's
        cross-validation (at most 3 there).
    param_grid : dict, optional
        Hyper-parameters of an estimator ``classifier`` to choose by time-blocked cross-validation
        (:class:`~fdikit.isolate.svm.BlockedStratifiedKFold`, a gap of ``window`` samples).
    accept_miscalibrated : bool
        Keep a design whose held-out false-alarm rate contradicts ``pfa`` (with a ``UserWarning``)
        instead of refusing it.
    unknown : str
        The answer above the gate of an isolator trained on nominal samples only.

    Attributes
    ----------
    design_report_ : dict
        ``target``, ``threshold``, ``held_out_rate``, ``interval`` (95 %, moving-block bootstrap),
        ``samples``, ``effective_samples``, ``method``, and how the gate was estimated.
    classifier_ : str
        The classifier chosen (``"lda"``, ``"forest"``, the estimator's class name, or ``None``).

    Examples
    --------
    >>> from fdikit.evaluate.synthetic import labelled_residuals, time_split
    >>> d = labelled_residuals(30000, channels=4, faults=2, magnitude=(3.0, 5.0), seed=3)
    >>> tr, te = time_split(len(d.labels))
    >>> iso = WindowedIsolator(window=50, pfa=0.01).fit(d.r[tr], d.labels[tr], d.condition[tr])
    >>> pred = iso.predict(d.r[te], d.condition[te])
    >>> lab = d.labels[te]
    >>> bool(np.mean(pred[lab != "nominal"] == lab[lab != "nominal"]) > 0.9)   # faults isolated
    True
    >>> rep = iso.design_report_
    >>> bool(rep["interval"][0] <= 0.01 <= rep["interval"][1])   # the claim holds on held-out data
    True
    """

    def __init__(self, window: int = 50, pfa: float = 0.01, classifier: Any = "auto", *,
                 nominal: str = "nominal", max_train: int = 6000, random_state: int = 0,
                 covariance: str = "oas", rank: int | None = None, calibration: str = "interleaved",
                 holdout: float = 0.5, folds: int = 5, param_grid: dict | None = None,
                 accept_miscalibrated: bool = False, unknown: str = "unknown"):
        if int(window) != window or window < 1:
            raise DataError(f"window must be an integer >= 1 sample, got {window}")
        if not 0 < pfa < 1:
            raise DataError(f"pfa must lie in (0, 1), got {pfa}")
        if covariance not in COVARIANCES:
            raise DataError(f"unknown covariance {covariance!r}; use one of {COVARIANCES}")
        if rank is not None and (int(rank) != rank or rank < 1):
            raise DataError(f"rank must be an integer >= 1 or None, got {rank}")
        if calibration not in CALIBRATIONS:
            raise DataError(f"unknown calibration {calibration!r}; use one of {CALIBRATIONS}")
        if not 0 < holdout < 1:
            raise DataError(f"holdout must lie in (0, 1), got {holdout}")
        if int(folds) != folds or folds < 2:
            raise DataError(f"folds must be an integer >= 2, got {folds}")
        if isinstance(classifier, str) and classifier not in CLASSIFIERS:
            raise DataError(f"unknown classifier {classifier!r}; use one of {CLASSIFIERS} or an estimator")
        if param_grid is not None and isinstance(classifier, str):
            raise DataError("param_grid needs an estimator as classifier (e.g. RandomForestClassifier())")
        self.window, self.pfa, self.classifier = int(window), float(pfa), classifier
        self.nominal, self.max_train, self.random_state = str(nominal), int(max_train), int(random_state)
        self.covariance, self.rank = covariance, None if rank is None else int(rank)
        self.calibration, self.holdout, self.folds = calibration, float(holdout), int(folds)
        self.param_grid, self.accept_miscalibrated = param_grid, bool(accept_miscalibrated)
        self.unknown = str(unknown)
        self.gap_taus = 1.0

    def _features(self, r: Any) -> np.ndarray:
        F = moving_average(r, self.window)
        if not np.all(np.isfinite(F)):
            k, c = np.argwhere(~np.isfinite(F))[0]
            raise DataError(f"residual channel {c} is not finite near sample {k}")
        return F

    def _condition(self, condition: Any, T: int) -> np.ndarray:
        if condition is None:
            return np.zeros((T, 0))
        o = np.asarray(condition, dtype=float)
        o = o[:, None] if o.ndim == 1 else o
        if o.ndim != 2 or o.shape[0] != T:
            raise DataError(f"condition must be (T,) or (T, m) with T = {T} samples, got shape {o.shape}")
        return self._features(o)

    def _centred(self, r: Any, condition: Any) -> np.ndarray:
        F = self._features(r)
        O = self._condition(condition, F.shape[0])
        if O.shape[1] != self.B_.shape[0]:
            raise DataError(f"the isolator was fitted with {self.B_.shape[0]} condition signals, "
                            f"got {O.shape[1]}")
        return F - self.mu_ - O @ self.B_

    def gate_statistic(self, r: Any, condition: Any = None) -> np.ndarray:
        """Mahalanobis distance^2 of each sample's features from the nominal mean (T,)."""
        self._fitted()
        D = self._centred(r, condition)
        return np.einsum("tc,cd,td->t", D, self.P_, D)

    # ---- the nominal gate -------------------------------------------------------------------

    def _gate_model(self, F: np.ndarray, O: np.ndarray) -> tuple:
        """Nominal mean (regressed on the conditions), precision matrix and facts, from samples F, O."""
        from sklearn.covariance import OAS, LedoitWolf

        from ..detect.tail import block_length

        n, d = F.shape
        X = np.column_stack([np.ones(n), O])
        coef = np.linalg.lstsq(X, F, rcond=None)[0]
        mu, B = coef[0], coef[1:]
        D = F - mu - O @ B
        taus = [block_length(D[:, c])["tau"] for c in range(d)] if n >= 10 else [float(n)]
        tau = float(np.median(taus))
        n_eff = n / tau
        k = d if self.rank is None else min(self.rank, d)
        need = 2 * k if (self.covariance == "empirical" or self.rank is not None) else MIN_EFFECTIVE
        if n_eff < need:
            alt = max(1, int(n_eff // 2))
            raise DataError(
                f"the gate's {self.covariance} covariance of {d} features (rank {k}) from {n} nominal "
                f"samples ({n_eff:.0f} effective: autocorrelation time {tau:.1f}) needs at least {need} "
                f"effective samples (about {int(np.ceil(need * tau))} nominal samples in the fit part); give "
                "more nominal data"
                + (", covariance='oas' (shrinkage)" if self.covariance == "empirical" else "")
                + (f", or rank={alt} (the leading principal directions)" if alt < k
                   else ", or a shorter window"))
        if self.covariance == "empirical":
            cov = np.atleast_2d(np.cov(D.T))
            cov = cov + 1e-12 * np.trace(cov) * np.eye(d)
            shrink = 0.0
        else:
            est = (OAS if self.covariance == "oas" else LedoitWolf)(assume_centered=True).fit(D)
            cov, shrink = est.covariance_, float(est.shrinkage_)
        w, V = np.linalg.eigh(cov)
        if self.rank is not None:
            V, w = V[:, -k:], w[-k:]
        P = (V / w) @ V.T
        info = {"fit_samples": int(n), "fit_effective_samples": float(n_eff), "features": int(d),
                "rank": int(k), "covariance": self.covariance, "shrinkage": shrink,
                "condition_number": float(w.max() / w.min()) if w.min() > 0 else float("inf")}
        return mu, B, P, info

    @staticmethod
    def _d2(model: tuple, F: np.ndarray, O: np.ndarray) -> np.ndarray:
        mu, B, P = model[:3]
        D = F - mu - O @ B
        return np.einsum("tc,cd,td->t", D, P, D)

    def _design_gate(self, F: np.ndarray, O: np.ndarray, nidx: np.ndarray) -> None:
        """Fit the gate on one part of the nominal samples, set its threshold on another, check it."""
        from ..detect.tail import block_length, block_rate_ci

        n = nidx.size
        # parts closer than a few autocorrelation times share their noise: keep them apart
        tau = float(np.median([block_length(F[nidx, c])["tau"] for c in range(F.shape[1])]))
        gap = int(max(self.window, np.ceil(self.gap_taus * tau)))
        if self.calibration in ("holdout", "interleaved"):
            if self.calibration == "holdout":
                n_cal = round(self.holdout * n)
                cal = nidx[n - n_cal:]
                fit = nidx[nidx < cal[0] - gap]
            else:
                # alternate contiguous blocks: both parts span the whole record (its operating conditions)
                # each block at least BLOCK_TAUS autocorrelation times long, at most 2 folds blocks
                m = int(min(self.folds, max(1, n // (2 * BLOCK_TAUS * tau))))
                blocks = np.array_split(np.arange(n), 2 * m)
                cal_blocks = [nidx[b] for b in blocks[1::2]]
                cal = np.concatenate(cal_blocks)
                near = np.zeros(F.shape[0] + 2 * gap + 1, int)
                for b in cal_blocks:  # keep the fit part a gap away from every calibration block
                    near[max(0, b[0] - gap):b[-1] + gap + 1] = 1
                fit = nidx[(near[nidx] == 0) & ~np.isin(nidx, cal)]
            model = self._gate_model(F[fit], O[fit])
            d2 = self._d2(model, F[cal], O[cal])
        else:
            d2 = np.empty(n)
            for pos in np.array_split(np.arange(n), self.folds):
                ch = nidx[pos]
                train = nidx[(nidx < ch[0] - gap) | (nidx > ch[-1] + gap)]
                d2[pos] = self._d2(self._gate_model(F[train], O[train]), F[ch], O[ch])
            model = self._gate_model(F[nidx], O[nidx])
        q = 1.0 - self.pfa
        threshold = float(np.quantile(d2, q))
        # the check: each contiguous block judged by the threshold set on the other blocks
        e = np.zeros(d2.size, bool)
        for b in np.array_split(np.arange(d2.size), self.folds):
            rest = np.delete(d2, b)
            e[b] = d2[b] > np.quantile(rest, q)
        rate = float(e.mean())
        bl_d = block_length(d2)
        bl_e = block_length(e.astype(float)) if 0 < e.sum() < e.size else bl_d
        block = max(int(bl_d["block"]), int(bl_e["block"]))
        lo, hi = block_rate_ci(e[None, :], block, n_boot=400, seed=self.random_state)
        n_eff = float(d2.size / max(bl_e["tau"], bl_d["tau"]))
        # a 95 % Wilson score interval at the effective sample size as well: the block bootstrap
        # alone is too narrow when the record holds few blocks
        z = 1.959963984540054
        a = 1.0 + z * z / n_eff
        c = (rate + z * z / (2 * n_eff)) / a
        h = z * np.sqrt(rate * (1 - rate) / n_eff + z * z / (4 * n_eff**2)) / a
        lo, hi = max(0.0, min(lo, c - h)), min(1.0, max(hi, c + h))
        self.mu_, self.B_, self.P_ = model[:3]
        self.threshold_ = threshold
        ok = lo <= self.pfa <= hi and n_eff >= MIN_EFFECTIVE
        self.design_report_ = {
            "target": self.pfa, "threshold": threshold, "held_out_rate": rate,
            "interval": [float(lo), float(hi)],
            "level": 0.95, "samples": int(d2.size), "effective_samples": n_eff, "block": block,
            "method": f"{self.calibration}, {self.folds} time-blocked checks", "calibrated": bool(ok),
            **model[3]}
        self.gate_design_ = {"quantile_of": q, "rate_ci95": [float(lo), float(hi)], "block": block,
                             "n_eff": n_eff}
        if not ok:
            need = int(np.ceil(MIN_EFFECTIVE * d2.size / n_eff))
            why = ("the nominal data are not stationary enough for this claim" if n_eff >= MIN_EFFECTIVE else
                   f"fewer than {MIN_EFFECTIVE} effective samples cannot check the claim (the calibration "
                   f"data are strongly autocorrelated or not stationary; about {need} would do)")
            msg = (f"the nominal gate designed for a false-alarm rate {self.pfa:g} per sample measured "
                   f"{rate:.4g} on held-out nominal data (95 % interval {lo:.4g}-{hi:.4g}, {d2.size} "
                   f"samples, {n_eff:.1f} effective; {self.calibration}, covariance {self.covariance}, "
                   "condition number "
                   f"{model[3]['condition_number']:.3g}): {why}. Give more (or more representative) nominal "
                   "data, a shorter window, or accept_miscalibrated=True to keep the design")
            if not self.accept_miscalibrated:
                raise DataError(msg)
            warnings.warn(msg, UserWarning, stacklevel=3)

    # ---- fitting -------------------------------------------------------------------------------

    def _classifier(self, X: np.ndarray, y: np.ndarray) -> Any:
        """Choose (time-blocked cross-validation) and fit the classifier among the faults."""
        from sklearn.base import clone
        from sklearn.discriminant_analysis import LinearDiscriminantAnalysis
        from sklearn.ensemble import RandomForestClassifier
        from sklearn.model_selection import GridSearchCV, cross_val_score

        from .svm import BlockedStratifiedKFold

        k = int(min(3, self.folds, np.unique(y, return_counts=True)[1].min()))
        cv = BlockedStratifiedKFold(max(2, k), gap=self.window)
        c = self.classifier
        if isinstance(c, str):
            lda = LinearDiscriminantAnalysis()
            forest = RandomForestClassifier(n_estimators=100, min_samples_leaf=2,
                                            random_state=self.random_state)
            cands = {"lda": lda, "forest": forest} if c in ("auto", "default") else \
                {c: lda if c == "lda" else forest}
        else:
            est = clone(c)
            if self.param_grid is not None:
                est = GridSearchCV(est, self.param_grid, cv=cv)
            cands = {type(c).__name__: est}
        self.cv_scores_ = {}
        if len(cands) > 1:
            self.cv_scores_ = {name: float(np.mean(cross_val_score(clone(e), X, y, cv=cv)))
                               for name, e in cands.items()}
            name = max(self.cv_scores_, key=self.cv_scores_.get)
        else:
            name = next(iter(cands))
        self.classifier_ = name
        est = cands[name].fit(X, y)
        return est.best_estimator_ if isinstance(est, GridSearchCV) else est

    def fit(self, r: Any, labels: Any, condition: Any = None) -> WindowedIsolator:
        """Learn the nominal gate and the fault classifier from residuals ``r`` (T, C), labels (T,)
        and, optionally, measured operating conditions (T,) or (T, m). With nominal labels only,
        the gate alone is trained (novelty detection: ``predict`` answers nominal or ``unknown``)."""
        r = np.asarray(r, dtype=float)
        lab = np.asarray(labels).astype(str)
        if r.ndim != 2 or lab.shape != (r.shape[0],):
            raise DataError(f"residuals (T, C) and labels (T,) must match; got {r.shape} and {lab.shape}")
        F = self._features(r)
        O = self._condition(condition, F.shape[0])
        clean = np.ones(r.shape[0], bool)
        change = np.flatnonzero(lab[1:] != lab[:-1]) + 1
        for k in change:
            clean[k:k + self.window] = False
        clean[:self.window] = False
        if not np.any(lab == self.nominal):
            raise DataError(f"label {self.nominal!r} (the nominal class) not found in the labels "
                            f"{sorted(set(lab.tolist()))[:12]}; pass nominal='<your nominal label>'")
        nom = clean & (lab == self.nominal)
        n_nom = int(nom.sum())
        need = int(np.ceil(10.0 / self.pfa))
        if n_nom < need:
            raise DataError(f"{n_nom} clean nominal samples cannot design a gate at pfa {self.pfa} per "
                            f"sample; need at least {need} (10 / pfa)")
        self._design_gate(F, O, np.flatnonzero(nom))
        F = F - self.mu_ - O @ self.B_
        fault = clean & (lab != self.nominal)
        classes = sorted(set(lab[fault].tolist()))
        idx = np.flatnonzero(fault)
        if idx.size > self.max_train:
            idx = idx[np.linspace(0, idx.size - 1, self.max_train).round().astype(int)]
        counts = {c: int(np.sum(lab[idx] == c)) for c in classes}
        self.model_, self.only_, self.classifier_, self.cv_scores_ = None, None, None, {}
        if len(classes) == 1:
            self.only_ = classes[0]
        elif len(classes) > 1:
            small = {c: n for c, n in counts.items() if n < 5}
            if small:
                raise DataError(f"too few clean training samples for the faults {small} (need >= 5 each for "
                                "the cross-validation)")
            self.model_ = self._classifier(F[idx], lab[idx])
        self.classes_ = [self.nominal, *classes] if classes else [self.nominal, self.unknown]
        self.train_counts_ = {"nominal": n_nom, **counts}
        return self

    def _fitted(self) -> None:
        if not hasattr(self, "threshold_"):
            raise DataError("WindowedIsolator is not fitted: call fit(r, labels) first")

    def predict(self, r: Any, condition: Any = None) -> np.ndarray:
        """The diagnosis of every sample (T,): the nominal label below the gate, else a fault (or
        ``unknown`` when trained on nominal samples only)."""
        self._fitted()
        F = self._centred(r, condition)
        d2 = np.einsum("tc,cd,td->t", F, self.P_, F)
        out = np.full(F.shape[0], self.nominal, dtype=object)
        hit = d2 > self.threshold_
        if hit.any():
            if self.model_ is not None:
                out[hit] = self.model_.predict(F[hit])
            else:
                out[hit] = self.unknown if self.only_ is None else self.only_
        return out.astype(str)
