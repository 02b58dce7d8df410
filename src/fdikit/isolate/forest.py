"""Isolation by a scikit-learn ensemble on causal window features, with a rejection option
calibrated at a false-alarm target on held-out nominal windows.

On real residuals a default random forest over the window means isolates better than a nominal
gate plus a classifier among the faults (Tennessee Eastman, window 20: 0.67 against 0.63 mean
accuracy after the onset), but it says "fault" on most of a held-out nominal record (88 % of
``d00_te``): nothing sets its false-alarm rate. :class:`ForestIsolator` wraps such classifiers
instead of reimplementing a weaker one, and adds what they lack (on the same TEP windows with
``features="auto"``, mean + deviation chosen by time-blocked CV: 0.867 without a rejection, 0.847
naming the fault where a calibrated CVA detector alarms, at 0 % of ``d00_te`` alarmed;
``benchmarks/bench_tep.py``):

1. **features**: the causal mean of each residual over the last ``window`` samples of its own
   record (``groups``: windows never span two records); ``features="mean_std"`` adds the
   standard deviation over the same window (faults that change the variance, e.g. sticky valves),
   ``"mean_std_slope"`` the least-squares slope too (drifts); ``features="auto"`` chooses among
   them by the same time-blocked cross-validation as the classifier (every pair is scored);
2. **the classifier** among the nominal class and the faults, chosen by time-blocked
   cross-validation (:class:`~fdikit.isolate.svm.BlockedStratifiedKFold`: contiguous blocks of
   every class, ``window`` samples left out beside each validation block) from ``candidates``:
   ``"forest"`` (RandomForest), ``"extra_trees"`` (ExtraTrees), ``"hgb"``
   (HistGradientBoosting), ``"linear"`` (StandardScaler + logistic regression), or a given
   estimator;
3. **rejection**: the fault score ``s = 1 - P(nominal)`` of every nominal window is taken from
   the cross-validation (each window scored by a model that did not see its block); the
   threshold is their split-conformal quantile at ``1 - pfa``
   (:func:`fdikit.detect.held_out_limit`), with the interval of the rate it gives at the effective
   sample size (autocorrelated windows count ``n / tau``). Below the threshold a window is
   ``nominal``; above it, the most probable fault -- or ``unknown`` when that fault's share of the
   fault probability is below ``unknown_below``.

:attr:`ForestIsolator.design_report_` holds the claim and its interval; measure it on a nominal
record the design never saw (:meth:`ForestIsolator.false_alarm_rate`).
"""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np

from ..errors import DataError
from .classify import moving_average

__all__ = ["ForestIsolator", "window_features"]

CANDIDATES = ("forest", "extra_trees", "hgb", "linear")
FEATURES = ("mean", "mean_std", "mean_std_slope")


def window_features(r: Any, window: int, groups: Any = None, kind: str = "mean") -> np.ndarray:
    """Causal window features of residuals ``r`` (T, C), each record (``groups``) on its own.

    Parameters
    ----------
    r : array_like (T, C)
        Residuals (records laid end to end).
    window : int
        Samples in the window (fewer at the start of each record).
    groups : array_like (T,), optional
        Record of every sample; a window never reaches into the previous record. Default: one record.
    kind : "mean", "mean_std" or "mean_std_slope"
        The window mean of every channel; the mean and the standard deviation; those and the
        least-squares slope per sample (0 for a one-sample window).

    Returns
    -------
    ndarray (T, C), (T, 2 C) or (T, 3 C)
        Blocks of C columns in that order (means, then deviations, then slopes).

    Examples
    --------
    >>> import numpy as np
    >>> window_features(np.array([[1.0], [3.0], [5.0], [7.0]]), 2, groups=[0, 0, 1, 1]).ravel().tolist()
    [1.0, 2.0, 5.0, 6.0]
    """
    r = np.asarray(r, dtype=float)
    if r.ndim == 1:
        r = r[:, None]
    if r.ndim != 2:
        raise DataError(f"residuals must be (T, channels), got shape {r.shape}")
    if kind not in FEATURES:
        raise DataError(f"unknown features {kind!r}; use one of {FEATURES}")
    bad = ~np.isfinite(r)
    if bad.any():
        k, c = np.argwhere(bad)[0]
        raise DataError(f"residual channel {c} is not finite at sample {k}")
    g = _groups(groups, r.shape[0])
    out = np.empty((r.shape[0], r.shape[1] * (FEATURES.index(kind) + 1)))
    for s, e in _segments(g):
        m = moving_average(r[s:e], window)
        if kind == "mean":
            out[s:e] = m
            continue
        m2 = moving_average(r[s:e] ** 2, window)
        parts = [m, np.sqrt(np.maximum(m2 - m * m, 0.0))]
        if kind == "mean_std_slope":
            parts.append(_window_slope(r[s:e], window, m))
        out[s:e] = np.hstack(parts)
    return out


def _window_slope(x: np.ndarray, window: int, mean: np.ndarray) -> np.ndarray:
    """Least-squares slope per sample of every channel over the causal window (0 where it holds one
    sample); ``mean`` is the window mean (:func:`moving_average`)."""
    T = x.shape[0]
    j = np.arange(T, dtype=float)
    k = np.arange(1, T + 1)
    lo = np.maximum(k - int(window), 0)
    n = (k - lo).astype(float)
    cj = np.concatenate([[0.0], np.cumsum(j - j.mean())])
    cjx = np.vstack([np.zeros((1, x.shape[1])), np.cumsum((j - j.mean())[:, None] * x, axis=0)])
    jbar = (cj[k] - cj[lo]) / n                      # mean of the centred times in the window
    sxy = (cjx[k] - cjx[lo]) - (jbar * n)[:, None] * mean
    stt = (n ** 3 - n) / 12.0                        # sum of (j - jbar)^2 over n consecutive samples
    return np.where(n[:, None] > 1, sxy / np.where(n > 1, stt, 1.0)[:, None], 0.0)


def _groups(groups: Any, T: int) -> np.ndarray:
    if groups is None:
        return np.zeros(T, int)
    g = np.asarray(groups)
    if g.shape != (T,):
        raise DataError(f"groups must be (T,) with T = {T} samples, got shape {g.shape}")
    return g


def _segments(g: np.ndarray) -> list[tuple[int, int]]:
    """Contiguous runs of equal ``g``: [(start, end), ...]."""
    cut = np.flatnonzero(g[1:] != g[:-1]) + 1
    edges = [0, *cut.tolist(), g.size]
    return list(itertools.pairwise(edges))


class ForestIsolator:
    """Window features, a scikit-learn classifier over nominal and faults, a calibrated rejection.

    Parameters
    ----------
    window : int
        Samples of the causal window.
    pfa : float or None
        Per-sample false-alarm probability of the rejection (a nominal window called a fault);
        None: no rejection (the classifier's most probable class).
    classifier : "auto", one of ``candidates`` or a scikit-learn classifier
        ``"auto"``: the candidate with the best time-blocked cross-validated accuracy.
    candidates : tuple of str
        Tried by ``"auto"`` (see the module docstring).
    features : "mean", "mean_std", "mean_std_slope" or "auto"
        See :func:`window_features`; ``"auto"``: every kind with every classifier tried, the pair
        with the best time-blocked cross-validated accuracy kept.
    nominal, unknown : str
        The nominal label; the answer above the threshold when no fault is clear enough.
    unknown_below : float, optional
        Above the threshold, answer ``unknown`` when the top fault's share of the fault
        probability is below this (default None: always name a fault).
    folds : int
        Time-blocked cross-validation folds (classifier choice and the held-out nominal scores).
    n_estimators : int
        Trees of the forests.
    class_weight : None, "balanced" or dict
        Of the built-in candidates (scikit-learn's meaning): ``"balanced"`` weighs a class by the
        inverse of its frequency (a nominal class much smaller than the faults' counts as much).
    confidence : float
        Of the interval of the rejection's false-alarm rate.
    random_state : int

    Attributes
    ----------
    classifier_ : str
        The classifier used.
    features_ : str
        The window features used (the chosen kind with ``features="auto"``).
    cv_scores_ : dict
        Time-blocked cross-validated accuracy of every candidate (``"<classifier>/<features>"``
        keys with ``features="auto"``).
    threshold_ : float or None
        Of the fault score ``1 - P(nominal)`` (None with ``pfa=None``: no rejection).
    design_report_ : dict
        ``target``, ``threshold``, ``interval``, ``samples``, ``effective_samples``, ``supported``,
        ``held_out_rate`` (of the cross-validated nominal scores), ``classifier``, ``cv_scores``;
        :meth:`calibrate` sets the threshold again on more nominal records.
    classes_ : list of str

    Examples
    --------
    >>> from fdikit.evaluate.synthetic import labelled_residuals, time_split
    >>> d = labelled_residuals(12000, channels=4, faults=2, magnitude=(3.0, 5.0), seed=3)
    >>> tr, te = time_split(len(d.labels))
    >>> iso = ForestIsolator(window=50, pfa=0.01, candidates=("forest", "linear"), n_estimators=50)
    >>> iso = iso.fit(d.r[tr], d.labels[tr])
    >>> pred, lab = iso.predict(d.r[te]), d.labels[te]
    >>> bool(np.mean(pred[lab != "nominal"] == lab[lab != "nominal"]) > 0.8)
    True
    >>> sorted(iso.outcomes(d.r[te][:5]))
    ['S_F1', 'S_F2', 'S_nominal']
    """

    def __init__(self, window: int = 20, pfa: float | None = 0.01, classifier: Any = "auto", *,
                 candidates: tuple[str, ...] = ("forest", "extra_trees"), features: str = "mean",
                 nominal: str = "nominal", unknown: str = "unknown", unknown_below: float | None = None,
                 folds: int = 3, n_estimators: int = 100, class_weight: Any = None, confidence: float = 0.95,
                 random_state: int = 0):
        if int(window) != window or window < 1:
            raise DataError(f"window must be an integer >= 1 sample, got {window}")
        if pfa is not None and not 0 < pfa < 1:
            raise DataError(f"pfa must lie in (0, 1) or be None, got {pfa}")
        bad = [c for c in candidates if c not in CANDIDATES]
        if bad or not candidates:
            raise DataError(f"unknown candidates {bad}; use some of {CANDIDATES}")
        if isinstance(classifier, str) and classifier != "auto" and classifier not in CANDIDATES:
            raise DataError(f"unknown classifier {classifier!r}; use 'auto', one of {CANDIDATES} or an "
                            "estimator")
        if features not in (*FEATURES, "auto"):
            raise DataError(f"unknown features {features!r}; use 'auto' or one of {FEATURES}")
        if int(folds) != folds or folds < 2:
            raise DataError(f"folds must be an integer >= 2, got {folds}")
        if unknown_below is not None and not 0 < unknown_below < 1:
            raise DataError(f"unknown_below must lie in (0, 1) or be None, got {unknown_below}")
        self.window, self.pfa, self.classifier = int(window), None if pfa is None else float(pfa), classifier
        self.candidates, self.features = tuple(candidates), features
        self.nominal, self.unknown, self.unknown_below = str(nominal), str(unknown), unknown_below
        self.folds, self.n_estimators = int(folds), int(n_estimators)
        self.confidence, self.random_state = float(confidence), int(random_state)
        self.class_weight = class_weight

    # ---- the classifiers -------------------------------------------------------------------

    def _make(self, name: str) -> Any:
        from sklearn.ensemble import (
            ExtraTreesClassifier,
            HistGradientBoostingClassifier,
            RandomForestClassifier,
        )
        from sklearn.linear_model import LogisticRegression
        from sklearn.pipeline import make_pipeline
        from sklearn.preprocessing import StandardScaler

        rs, cw = self.random_state, self.class_weight
        if name == "forest":
            return RandomForestClassifier(n_estimators=self.n_estimators, class_weight=cw, random_state=rs)
        if name == "extra_trees":
            return ExtraTreesClassifier(n_estimators=self.n_estimators, class_weight=cw, random_state=rs)
        if name == "hgb":
            return HistGradientBoostingClassifier(class_weight=cw, random_state=rs)
        return make_pipeline(StandardScaler(), LogisticRegression(class_weight=cw, max_iter=2000))

    def _oof(self, est: Any, X: np.ndarray, y: np.ndarray, cv: Any) -> np.ndarray:
        """Out-of-fold class probabilities (n, classes) in the order of ``np.unique(y)``."""
        from sklearn.base import clone

        classes = np.unique(y)
        P = np.zeros((X.shape[0], classes.size))
        for tr, te in cv.split(X, y):
            m = clone(est).fit(X[tr], y[tr])
            cols = np.searchsorted(classes, m.classes_)
            P[np.ix_(te, cols)] = m.predict_proba(X[te])
        return P

    # ---- fitting ---------------------------------------------------------------------------

    def fit(self, r: Any, labels: Any, groups: Any = None) -> ForestIsolator:
        """Learn the classifier and the rejection threshold.

        Parameters
        ----------
        r : array_like (T, C)
            Residuals (or any signals), records laid end to end in time order.
        labels : array_like (T,)
            The class of every sample (``nominal`` for fault-free ones).
        groups : array_like (T,), optional
            The record of every sample (windows stay inside a record). A new segment also starts
            where the label changes; its first ``window`` samples (mixed windows) are left out.

        Returns
        -------
        ForestIsolator
        """
        from sklearn.base import clone

        from .svm import BlockedStratifiedKFold

        r = np.asarray(r, dtype=float)
        lab = np.asarray(labels).astype(str)
        if r.ndim != 2 or lab.shape != (r.shape[0],):
            raise DataError(f"residuals (T, C) and labels (T,) must match; got {r.shape} and {lab.shape}")
        if not np.any(lab == self.nominal):
            raise DataError(f"label {self.nominal!r} (the nominal class) not found in the labels "
                            f"{sorted(set(lab.tolist()))[:12]}; pass nominal='<your nominal label>'")
        g = _groups(groups, r.shape[0])
        seg = np.zeros(r.shape[0], int)                 # a new segment at every record or label change
        change = (g[1:] != g[:-1]) | (lab[1:] != lab[:-1])
        seg[1:] = np.cumsum(change)
        kinds = list(FEATURES) if self.features == "auto" else [self.features]
        keep = np.ones(r.shape[0], bool)
        for s, _ in _segments(seg):
            keep[s:s + self.window] = False
        Xs = {kind: window_features(r, self.window, seg, kind)[keep] for kind in kinds}
        y = lab[keep]
        counts = {c: int(np.sum(y == c)) for c in np.unique(y)}
        small = {c: n for c, n in counts.items() if n < 2 * self.folds}
        if small:
            raise DataError(f"too few full windows (window {self.window}) for the classes {small}; need at "
                            f"least {2 * self.folds} each (2 per fold)")
        if len(counts) < 2:
            raise DataError("ForestIsolator needs the nominal class and at least one fault class; for "
                            "novelty detection from nominal data only use WindowedIsolator")
        cv = BlockedStratifiedKFold(self.folds, gap=self.window)
        if isinstance(self.classifier, str):
            names = list(self.candidates) if self.classifier == "auto" else [self.classifier]
            cands = {n: self._make(n) for n in names}
        else:
            cands = {type(self.classifier).__name__: clone(self.classifier)}
        classes = np.unique(y)
        oof, self.cv_scores_, pairs = {}, {}, {}
        for kind, X in Xs.items():
            for name, est in cands.items():
                key = f"{name}/{kind}" if len(Xs) > 1 else name
                P = self._oof(est, X, y, cv)
                oof[key], pairs[key] = P, (name, kind)
                self.cv_scores_[key] = float(np.mean(classes[np.argmax(P, axis=1)] == y))
        best = max(self.cv_scores_, key=self.cv_scores_.get)
        name, self.features_ = pairs[best]
        X = Xs[self.features_]
        self.classifier_ = name
        self.model_ = clone(cands[name]).fit(X, y)
        self.classes_ = [str(c) for c in self.model_.classes_]
        self._inom = self.classes_.index(self.nominal)
        # rejection: the out-of-fold fault scores of the nominal windows, per contiguous nominal segment
        P = oof[best]
        score = 1.0 - P[:, int(np.searchsorted(classes, self.nominal))]
        segs = seg[keep]
        nom = y == self.nominal
        recs = [score[nom & (segs == s)] for s in np.unique(segs[nom])]
        rep: dict[str, Any] = {"target": self.pfa, "classifier": name, "cv_scores": dict(self.cv_scores_),
                               "nominal_windows": int(nom.sum()), "features": self.features_,
                               "window": self.window}
        self.design_report_ = rep
        self.oof_scores_ = recs
        self.threshold_ = None
        if self.pfa is not None:
            self._set_threshold(recs, f"{self.folds} time-blocked folds: out-of-fold P(nominal) of the "
                                      "nominal windows, split-conformal quantile")
        self.n_features_ = X.shape[1] // (FEATURES.index(self.features_) + 1)
        return self

    def _set_threshold(self, recs: list, method: str) -> None:
        from ..detect.calibrated_limits import held_out_limit

        d = held_out_limit(recs, 1.0 - self.pfa, confidence=self.confidence)
        self.threshold_ = d["limit"]
        allv = np.concatenate(recs)
        self.design_report_.update({
            "threshold": d["limit"], "interval": d["interval"], "samples": d["samples"],
            "effective_samples": d["effective_samples"], "tau": d["tau"], "supported": d["supported"],
            "confidence": self.confidence, "held_out_rate": float(np.mean(allv > d["limit"])),
            "method": method})

    def calibrate(self, r: Any = None, groups: Any = None, *, scores: Any = None,
                  include_training: bool = True) -> ForestIsolator:
        """Set the rejection threshold again, on more nominal records the classifier never saw.

        The fault scores of the given records (by the fitted model) are pooled with the
        out-of-fold scores of the training's nominal windows (``include_training``) and the
        threshold is their split-conformal quantile at ``1 - pfa``, as in :meth:`fit`; the
        classifier is unchanged. More nominal records (other runs of the process) give more
        effective samples and a threshold that covers their run-to-run variation.

        Parameters
        ----------
        r : array_like (T, C), optional
            Nominal residuals (records laid end to end; ``groups`` tells them apart). Their first
            ``window - 1`` samples per record (partial windows) are left out.
        groups : array_like (T,), optional
        scores : list of arrays, optional
            Fault scores (:meth:`fault_score`) of nominal records, instead of ``r``.
        include_training : bool
            Pool the training's out-of-fold nominal scores as well.

        Returns
        -------
        ForestIsolator
        """
        self._fitted()
        if self.pfa is None:
            raise DataError("pfa=None: the isolator has no rejection to calibrate")
        recs = list(self.oof_scores_) if include_training else []
        if r is not None:
            s = self.fault_score(r, groups)
            g = _groups(groups, s.size)
            recs += [s[a + self.window - 1:b] for a, b in _segments(g) if b - a >= self.window]
        if scores is not None:
            recs += [np.asarray(v, dtype=float).ravel() for v in scores]
        if not recs:
            raise DataError("calibrate needs nominal records (r or scores) or include_training=True")
        more = len(recs) - (len(self.oof_scores_) if include_training else 0)
        self._set_threshold(recs, "split-conformal quantile of the fault scores of held-out nominal windows ("
                            + ("training out-of-fold + " if include_training else "")
                            + f"{more} more records)")
        return self

    # ---- running ---------------------------------------------------------------------------

    def _fitted(self) -> None:
        if not hasattr(self, "model_"):
            raise DataError("ForestIsolator is not fitted: call fit(r, labels) first")

    def _X(self, r: Any, groups: Any) -> np.ndarray:
        r = np.asarray(r, dtype=float)
        r = r[:, None] if r.ndim == 1 else r
        if r.ndim != 2 or r.shape[1] != self.n_features_:
            raise DataError(f"the isolator was fitted on {self.n_features_} channels, got residuals of shape "
                            f"{r.shape}")
        return window_features(r, self.window, groups, self.features_)

    def predict_proba(self, r: Any, groups: Any = None) -> np.ndarray:
        """Class probabilities of every sample's window (T, classes), columns in :attr:`classes_`."""
        self._fitted()
        return self.model_.predict_proba(self._X(r, groups))

    def fault_score(self, r: Any, groups: Any = None) -> np.ndarray:
        """``1 - P(nominal)`` of every sample (T,): the statistic the rejection thresholds."""
        return 1.0 - self.predict_proba(r, groups)[:, self._inom]

    def predict(self, r: Any, groups: Any = None, *, reject: bool = True, detected: Any = None) -> np.ndarray:
        """The diagnosis of every sample (T,).

        Parameters
        ----------
        r : array_like (T, C)
        groups : array_like (T,), optional
        reject : bool
            ``nominal`` below the rejection threshold, else the most probable fault (or
            ``unknown``); False (or ``pfa=None``): the most probable class.
        detected : array_like (T,) of bool, optional
            Alarms of another detector with its own calibrated false-alarm rate (e.g. a CVA
            index at a held-out limit, :func:`fdikit.detect.held_out_limit`): they replace the
            rejection (``nominal`` where False, the most probable fault where True).

        Returns
        -------
        ndarray (T,) of str
        """
        P = self.predict_proba(r, groups)
        cls = np.asarray(self.classes_, dtype=object)
        if detected is not None:
            hit = np.asarray(detected, dtype=bool)
            if hit.shape != (P.shape[0],):
                raise DataError(f"detected must be (T,) booleans with T = {P.shape[0]}, got shape "
                                f"{hit.shape}")
        elif not reject or self.threshold_ is None:
            return cls[np.argmax(P, axis=1)].astype(str)
        else:
            hit = (1.0 - P[:, self._inom]) > self.threshold_
        out = np.full(P.shape[0], self.nominal, dtype=object)
        Pf = P.copy()
        Pf[:, self._inom] = -1.0
        top = np.argmax(Pf, axis=1)
        out[hit] = cls[top[hit]]
        if self.unknown_below is not None:
            share = P[np.arange(P.shape[0]), top] / np.maximum(1.0 - P[:, self._inom], 1e-300)
            out[hit & (share < self.unknown_below)] = self.unknown
        return out.astype(str)

    def false_alarm_rate(self, r: Any, groups: Any = None) -> dict[str, Any]:
        """Measured rate of fault answers on a nominal record, beside the claim and its interval.

        Returns
        -------
        dict
            ``measured``, ``target``, ``interval`` (of the rate the design claims) and
            ``predictive`` (the interval a record of this length may measure: the claim's
            uncertainty plus the record's own noise), ``within`` (measured inside ``predictive``).
        """
        from ..detect.calibrated_limits import predictive_interval

        self._fitted()
        if self.threshold_ is None:
            raise DataError("pfa=None: the isolator has no rejection and claims no false-alarm rate")
        pred = self.predict(r, groups)
        rate = float(np.mean(pred != self.nominal))
        rep = self.design_report_
        iv = predictive_interval(1.0 - self.pfa, rep["effective_samples"], rep["tau"], pred.size,
                                 self.confidence)
        return {"measured": rate, "target": self.pfa, "interval": rep["interval"], "predictive": iv,
                "within": bool(iv[0] <= rate <= iv[1])}

    def outcomes(self, r: Any, groups: Any = None) -> dict[str, np.ndarray]:
        """Binary outcomes ``{S_<label>: (T,) int}``, 1 where the sample is diagnosed as ``label``."""
        p = self.predict(r, groups)
        labels = list(self.classes_) + ([self.unknown] if self.unknown_below is not None else [])
        return {f"S_{c}": (p == c).astype(int) for c in labels}

    def __repr__(self) -> str:
        return (f"ForestIsolator(window={self.window}, pfa={self.pfa}, classifier="
                f"{getattr(self, 'classifier_', self.classifier)!r}, features="
                f"{getattr(self, 'features_', self.features)!r})")
