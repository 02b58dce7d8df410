"""SVM isolation for any labelled pattern set (after luo-et-al, Section VI and Appendix A).

Faults that move the residuals alike can be told apart by a classifier trained on labelled records
(simulated or real). :class:`SVMIsolator` wraps a scikit-learn pipeline: ``fit``/``predict``, the
binary test outcomes ``S_<label>`` of a D-matrix, and :meth:`SVMIsolator.export`, a plain-data
(JSON-able) form of the trained RBF decision function (eq. (42)) that :class:`SVMDecision`
evaluates with numpy alone -- no pickle.

The default pipeline (:func:`cv_pipeline`) standardises the features and chooses the RBF width and
box constraint by cross-validation on the training data, so it needs no tuning for a new system.
Its folds are time-blocked (:class:`BlockedStratifiedKFold`: contiguous blocks of every class, in
the order given, no shuffling): samples of one record or one long log are autocorrelated, and a
shuffled fold puts the neighbours of every validation sample in the training part, which rewards
over-fitting. ``cv_pipeline(shuffle=True)`` gives the shuffled stratified folds back (right for
independent patterns only). :class:`WindowFeatures` (window means of any linear combination of channels) turns
records laid end to end (:func:`concat_measurements`) into compact features. The ABS paper's
pipelines (raw patterns with sigma = 20, C = 1, and the slip-speed window means) are in
:mod:`fdikit.systems.abs.svm`.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.model_selection import BaseCrossValidator, GridSearchCV, StratifiedKFold
from sklearn.pipeline import Pipeline
from sklearn.preprocessing import StandardScaler
from sklearn.svm import SVC

from ..errors import DataError

__all__ = [
    "BlockedStratifiedKFold",
    "SVMDecision",
    "SVMIsolator",
    "WindowFeatures",
    "concat_measurements",
    "cv_pipeline",
    "rbf_gamma",
]


def rbf_gamma(sigma: float) -> float:
    """scikit-learn's ``gamma`` for an RBF width ``sigma``: ``1 / (2 sigma^2)`` (Appendix A).

    Examples
    --------
    >>> from fdikit.isolate.svm import rbf_gamma
    >>> rbf_gamma(20.0)
    0.00125
    """
    if not sigma > 0:
        raise DataError(f"RBF width sigma must be > 0, got {sigma}")
    return 1.0 / (2.0 * float(sigma) ** 2)


def concat_measurements(y: Any) -> np.ndarray:
    """Patterns ``[y_1 | y_2 | ...]``: each record's channels laid end to end (eq. (36), Fig. 12).

    Parameters
    ----------
    y : array_like (runs, T, p) or Signals
        Measurements of ``runs`` records.

    Returns
    -------
    ndarray (runs, T·p)
        Channel blocks of T samples each (ABS: wheel speed in 0..1249, vehicle speed 1250..2499).

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit.isolate.svm import concat_measurements
    >>> concat_measurements(np.arange(12.0).reshape(2, 3, 2))[0].tolist()
    [0.0, 2.0, 4.0, 1.0, 3.0, 5.0]
    """
    v = getattr(y, "values", y)
    v = np.asarray(v, dtype=float)
    if v.ndim == 2:
        v = v[None]
    if v.ndim != 3:
        raise DataError(f"measurements must be (runs, T, channels), got shape {np.shape(v)}")
    return np.ascontiguousarray(np.swapaxes(v, 1, 2).reshape(v.shape[0], -1))


class WindowFeatures(TransformerMixin, BaseEstimator):
    """Window means of a linear combination of channels of concatenated patterns.

    Parameters
    ----------
    n_channels : int
        Channels laid end to end in each pattern (the pattern length is ``n_channels · T``).
    window : int
        Samples per window (the last partial window is dropped).
    combination : sequence of float, optional
        Weights of the channels, e.g. ``(-1, 1)`` for ``y_2 - y_1`` (ABS: the slip speed
        ``omega_v - omega_w``). Default: every channel separately.

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit.isolate.svm import WindowFeatures
    >>> X = np.array([[1.0, 2.0, 3.0, 4.0, 10.0, 10.0, 10.0, 10.0]])
    >>> WindowFeatures(2, 2, (-1.0, 1.0)).fit_transform(X).tolist()
    [[8.5, 6.5]]
    """

    def __init__(self, n_channels: int, window: int, combination: Sequence[float] | None = None):
        self.n_channels = n_channels
        self.window = window
        self.combination = combination

    def _check(self, X: Any) -> np.ndarray:
        X = np.asarray(X, dtype=float)
        if X.ndim != 2 or X.shape[1] % int(self.n_channels):
            raise DataError(f"patterns must be (n, {self.n_channels}·T); got shape {X.shape}")
        T = X.shape[1] // int(self.n_channels)
        if not 1 <= int(self.window) <= T:
            raise DataError(f"window {self.window} must lie in 1..{T} samples")
        if self.combination is not None and len(self.combination) != int(self.n_channels):
            raise DataError(f"combination has {len(self.combination)} weights for {self.n_channels} channels")
        if not np.all(np.isfinite(X)):
            i, j = np.argwhere(~np.isfinite(X))[0]
            raise DataError(f"pattern {i} has NaN/inf at position {j}")
        return X

    def fit(self, X: Any, y: Any = None) -> WindowFeatures:
        X = self._check(X)
        self.n_features_in_ = X.shape[1]
        return self

    def transform(self, X: Any) -> np.ndarray:
        X = self._check(X)
        n, c, w = X.shape[0], int(self.n_channels), int(self.window)
        Z = X.reshape(n, c, -1)
        if self.combination is not None:
            Z = np.einsum("c,nct->nt", np.asarray(self.combination, float), Z)[:, None, :]
        k = Z.shape[2] // w
        return Z[:, :, : k * w].reshape(n, Z.shape[1], k, w).mean(axis=3).reshape(n, -1)


class BlockedStratifiedKFold(BaseCrossValidator):
    """Time-blocked stratified folds: every class's samples, in the order given, cut into
    ``n_splits`` contiguous blocks; fold ``k`` validates on block ``k`` of every class.

    No shuffling: a validation block's neighbours in time are not in the training part (up to its
    two edges; ``gap`` samples on either side of every validation block are left out of the
    training part as well). Give the samples in time order (records laid end to end).

    Parameters
    ----------
    n_splits : int
        Folds (>= 2).
    gap : int
        Samples (positions in the given order) left out of the training part next to each
        validation sample's block (default 0).

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit.isolate.svm import BlockedStratifiedKFold
    >>> y = np.array(list("aaaaaabbbb"))
    >>> [te.tolist() for _, te in BlockedStratifiedKFold(2).split(np.zeros((10, 1)), y)]
    [[0, 1, 2, 6, 7], [3, 4, 5, 8, 9]]
    """

    def __init__(self, n_splits: int = 5, gap: int = 0):
        if int(n_splits) != n_splits or n_splits < 2:
            raise DataError(f"n_splits must be an integer >= 2 folds, got {n_splits}")
        if int(gap) != gap or gap < 0:
            raise DataError(f"gap must be an integer >= 0 samples, got {gap}")
        self.n_splits, self.gap = int(n_splits), int(gap)

    def get_n_splits(self, X: Any = None, y: Any = None, groups: Any = None) -> int:
        return self.n_splits

    def split(self, X: Any, y: Any = None, groups: Any = None):
        n = len(X)
        lab = np.zeros(n, int) if y is None else np.asarray(y)
        if lab.shape[0] != n:
            raise DataError(f"{n} samples but {lab.shape[0]} labels")
        parts = [np.array_split(np.flatnonzero(lab == c), self.n_splits) for c in np.unique(lab)]
        for k in range(self.n_splits):
            test = np.sort(np.concatenate([p[k] for p in parts]))
            block = np.zeros(n, bool)
            block[test] = True
            if self.gap:
                # leave out the gap next to the validation samples (a dilation of the mask)
                c = np.convolve(block.astype(int), np.ones(2 * self.gap + 1, int), mode="same")
                block = c > 0
            yield np.flatnonzero(~block), test


def cv_pipeline(
    features: Any = None,
    *,
    scale: bool = True,
    Cs: Sequence[float] = (0.1, 1.0, 10.0, 100.0, 1000.0),
    gammas: Sequence[Any] = ("scale", 1e-3, 1e-2, 0.1, 1.0),
    cv: Any = 5,
    random_state: int = 0,
    shuffle: bool = False,
) -> GridSearchCV:
    """[features ->] [StandardScaler ->] RBF SVC, with ``C`` and ``gamma`` cross-validated.

    The default of :class:`SVMIsolator`: it works for any number of channels and classes, because
    the features are standardised (so no channel's unit dominates the kernel) and the kernel width
    and box constraint are chosen on the training data by ``cv``-fold cross-validation. The folds
    are time-blocked by default (:class:`BlockedStratifiedKFold`: contiguous blocks of each class
    in the order given, not shuffled), because samples cut from one record are autocorrelated and a
    shuffled split validates on the neighbours of training samples.

    Parameters
    ----------
    features : sklearn transformer, optional
        A first step, e.g. :class:`WindowFeatures` (window means of channel combinations).
    scale : bool
        Standardise the features (default True).
    Cs, gammas : sequences
        Grid of the box constraint and of the RBF ``gamma`` (1/feature-unit^2; ``"scale"`` is
        scikit-learn's ``1 / (n_features · var(X))``).
    cv : int or scikit-learn splitter
        Folds of the cross-validation (on the training data only), or a splitter (e.g.
        :class:`~sklearn.model_selection.TimeSeriesSplit`, ``GroupKFold`` by record).
    random_state : int
        Seed of the fold shuffling (``shuffle=True`` only).
    shuffle : bool
        Shuffled stratified folds (:class:`~sklearn.model_selection.StratifiedKFold`) instead of
        the time-blocked ones: only for independent patterns (one per independent run).

    Examples
    --------
    >>> from fdikit.isolate.svm import cv_pipeline
    >>> sorted(cv_pipeline().param_grid), [n for n, _ in cv_pipeline().estimator.steps]
    (['svc__C', 'svc__gamma'], ['scale', 'svc'])
    """
    if hasattr(cv, "split"):
        folds = cv
    else:
        if isinstance(cv, bool) or int(cv) != cv or cv < 2:
            raise DataError(f"cv must be an integer >= 2 folds or a splitter, got {cv}")
        folds = (StratifiedKFold(int(cv), shuffle=True, random_state=random_state) if shuffle
                 else BlockedStratifiedKFold(int(cv)))
    steps: list[tuple[str, Any]] = []
    if features is not None:
        steps.append(("features", features))
    if scale:
        steps.append(("scale", StandardScaler()))
    steps.append(("svc", SVC(kernel="rbf")))
    return GridSearchCV(Pipeline(steps), {"svc__C": list(Cs), "svc__gamma": list(gammas)},
                        cv=folds)


def _check_folds(est: Any, lab: np.ndarray) -> None:
    """Refuse, with the counts, a stratified cross-validation that has fewer samples of a class than folds."""
    cv = getattr(est, "cv", None)
    if not isinstance(est, GridSearchCV) or cv is None:
        return
    if not isinstance(cv, (int, StratifiedKFold, BlockedStratifiedKFold)):
        return
    k = cv if isinstance(cv, int) else getattr(cv, "n_splits", None)
    if k is None:
        return
    classes, counts = np.unique(lab, return_counts=True)
    few = {c.item() if hasattr(c, "item") else c: int(n) for c, n in zip(classes, counts) if n < k}
    if few:
        allc = {c.item() if hasattr(c, "item") else c: int(n) for c, n in zip(classes, counts)}
        raise DataError(f"the stratified {k}-fold cross-validation of the SVM needs at least {k} samples of "
                        f"every class; too few: {few} (all counts: {allc}). Give more labelled samples, "
                        f"fewer folds (SVMIsolator(cv_pipeline(cv={max(2, min(counts))})) when the smallest "
                        "class has at least 2), or drop the rare classes")


class SVMIsolator:
    """An SVM isolation test for any labelled pattern set (luo-et-al, Section VI).

    Parameters
    ----------
    pipeline : "default" or sklearn estimator
        ``"default"``: :func:`cv_pipeline` (standardised features, cross-validated RBF SVC); or
        any classifier with fit/predict (a Pipeline ending in an RBF ``SVC`` can be exported).
    test_names : mapping label -> str, optional
        Names of the binary tests; default ``"S_" + label`` without underscores
        (``"K_f" -> "S_Kf"``).

    Attributes
    ----------
    classes_ : ndarray
        Labels seen in ``fit``.
    estimator_ : fitted estimator (the best one after a grid search)
    fit_time_ : float
        Seconds spent in ``fit`` (including cross-validation).

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit.isolate.svm import SVMIsolator
    >>> rng = np.random.default_rng(0)
    >>> X = np.vstack([rng.normal(0, 1, (20, 4)), rng.normal(3, 1, (20, 4))])
    >>> lab = np.array(["K_f"] * 20 + ["I_w"] * 20)
    >>> iso = SVMIsolator().fit(X, lab)
    >>> iso.error(X, lab) < 0.1, sorted(iso.outcomes(X[:1]))
    (True, ['S_Iw', 'S_Kf'])
    """

    def __init__(self, pipeline: Any = "default", test_names: Mapping[Any, str] | None = None):
        self.pipeline = pipeline
        self.test_names = dict(test_names or {})

    def _make(self) -> Any:
        from sklearn.base import clone

        if isinstance(self.pipeline, str):
            if self.pipeline == "default":
                return cv_pipeline()
            raise DataError(f"unknown pipeline {self.pipeline!r}; use 'default' (cv_pipeline()) or a "
                            "scikit-learn estimator")
        return clone(self.pipeline)

    @staticmethod
    def _xy(X: Any, labels: Any = None) -> tuple[np.ndarray, np.ndarray | None]:
        X = np.asarray(getattr(X, "values", X), dtype=float)
        if X.ndim == 3:
            X = concat_measurements(X)
        if X.ndim != 2:
            raise DataError(f"patterns must be (n, features) or (runs, T, channels); got shape {X.shape}")
        if not np.all(np.isfinite(X)):
            i, j = np.argwhere(~np.isfinite(X))[0]
            raise DataError(f"pattern {i} has NaN/inf at position {j}")
        if labels is None:
            return X, None
        lab = np.asarray(labels)
        if lab.shape != (X.shape[0],):
            raise DataError(f"{X.shape[0]} patterns but labels have shape {lab.shape}")
        return X, lab

    def fit(self, X: Any, labels: Any) -> SVMIsolator:
        """Train on patterns ``X`` (n, features) or records (runs, T, channels) with ``labels`` (n,)."""
        X, lab = self._xy(X, labels)
        if np.unique(lab).size < 2:
            raise DataError(f"need at least two classes to train, got {np.unique(lab).tolist()}")
        est = self._make()
        _check_folds(est, lab)
        t0 = time.perf_counter()
        try:
            est = est.fit(X, lab)
        except ValueError as exc:
            # scikit-learn buries the cause in a long text (often per fold): give its last line with context
            lines = [ln.strip() for ln in str(exc).strip().splitlines() if ln.strip()]
            raise DataError(f"scikit-learn could not fit {type(est).__name__} on {X.shape[0]} patterns x "
                            f"{X.shape[1]} features, {len(np.unique(lab))} classes: "
                            f"{lines[-1] if lines else exc!r}") from exc
        self.fit_time_ = time.perf_counter() - t0
        self.search_ = est if isinstance(est, GridSearchCV) else None
        self.estimator_ = est.best_estimator_ if isinstance(est, GridSearchCV) else est
        self.classes_ = np.asarray(self.estimator_.classes_)
        self._check_test_names()
        return self

    def _check_test_names(self) -> None:
        """Two classes whose tests share a name would lose one outcome: refused, naming both."""
        seen: dict[str, Any] = {}
        for c in self.classes_:
            name = self.test_name(c)
            if name in seen:
                raise DataError(f"classes {str(seen[name])!r} and {str(c)!r} both give the test name "
                                f"{name!r} (the "
                                "default drops underscores); name the tests with test_names={label: name}")
            seen[name] = c

    def _fitted(self) -> None:
        if not hasattr(self, "estimator_"):
            raise DataError("SVMIsolator is not fitted: call fit(X, labels) first")

    def predict(self, X: Any) -> np.ndarray:
        """Predicted labels (n,)."""
        self._fitted()
        return self.estimator_.predict(self._xy(X)[0])

    def error(self, X: Any, labels: Any) -> float:
        """Fraction of misclassified patterns."""
        X, lab = self._xy(X, labels)
        return float(np.mean(self.predict(X) != lab))

    def test_name(self, label: Any) -> str:
        return self.test_names.get(label, "S_" + str(label).replace("_", ""))

    def outcomes(self, X: Any) -> dict[str, np.ndarray]:
        """Binary test outcomes: ``{S_<label>: (n,) int}``, 1 where the pattern is classified as ``label``."""
        p = self.predict(X)
        return {self.test_name(c): (p == c).astype(int) for c in self.classes_}

    def export(self) -> dict[str, Any]:
        """The trained decision function as plain data (lists and floats; JSON-able).

        Holds the feature step (:class:`WindowFeatures` settings), the scaler (mean, scale), the
        RBF ``gamma``, the support vectors, dual coefficients ``alpha_i z_i`` and intercepts
        ``b`` of eq. (42). Two classes: one decision function (version 1). More classes: the
        one-vs-one decision functions of scikit-learn's ``SVC`` (version 2: ``n_support`` per class,
        ``dual_coef`` (n_classes - 1, n_SV), one ``intercept`` per pair in the order (0, 1), (0, 2),
        ..., (1, 2), ...), which :class:`SVMDecision` evaluates by voting.
        """
        self._fitted()
        est = self.estimator_
        steps = est.steps if isinstance(est, Pipeline) else [("svc", est)]
        out: dict[str, Any] = {"kind": "fdikit.svm", "version": 1, "features": None, "scaler": None}
        for name, st in steps[:-1]:
            if isinstance(st, WindowFeatures):
                comb = None if st.combination is None else [float(c) for c in st.combination]
                out["features"] = {"n_channels": int(st.n_channels), "window": int(st.window),
                                   "combination": comb}
            elif isinstance(st, StandardScaler):
                out["scaler"] = {"mean": st.mean_.tolist(), "scale": st.scale_.tolist()}
            else:
                raise DataError(f"cannot export pipeline step {name!r} ({type(st).__name__})")
        svc = steps[-1][1]
        if not isinstance(svc, SVC) or svc.kernel != "rbf":
            raise DataError("export needs an RBF SVC as the last step")
        classes = [c.item() if hasattr(c, "item") else c for c in svc.classes_]
        if len(classes) == 2:
            out.update({"classes": classes, "gamma": float(svc._gamma),
                        "support_vectors": svc.support_vectors_.tolist(),
                        "dual_coef": svc.dual_coef_[0].tolist(), "intercept": float(svc.intercept_[0])})
            return out
        if getattr(svc, "break_ties", False):
            raise DataError("export of a multiclass SVC with break_ties=True is not supported (voting only)")
        out.update({"version": 2, "classes": classes, "gamma": float(svc._gamma),
                    "support_vectors": svc.support_vectors_.tolist(),
                    "n_support": [int(k) for k in svc.n_support_],
                    "dual_coef": svc.dual_coef_.tolist(), "intercept": svc.intercept_.tolist()})
        return out


class SVMDecision:
    """Numpy evaluation of an exported SVM (eq. (42)): no scikit-learn, no pickle.

    Two classes: ``f(y) = sum_i alpha_i z_i K(y, y_i) + b``; the pattern is of ``classes[1]`` when
    ``f > 0``. More classes: one such function per pair of classes ``(a, b)``, ``a < b``, over the
    support vectors of the two classes (libsvm's one-vs-one form, as scikit-learn's ``SVC``); ``a``
    gets the vote when ``f_ab > 0``, else ``b``; the class with the most votes wins, the first one on
    a tie (as libsvm).

    Examples
    --------
    >>> import numpy as np
    >>> from sklearn.svm import SVC
    >>> from fdikit.isolate.svm import SVMDecision, SVMIsolator
    >>> X = np.array([[0.0, 0.0], [0.1, 0.0], [3.0, 3.0], [3.1, 3.0]])
    >>> iso = SVMIsolator(SVC(kernel="rbf", gamma=0.5)).fit(X, ["a", "a", "b", "b"])
    >>> SVMDecision(iso.export()).predict(X).tolist()
    ['a', 'a', 'b', 'b']
    """

    def __init__(self, data: Mapping[str, Any]):
        if data.get("kind") != "fdikit.svm":
            raise DataError("not an exported fdikit SVM (kind != 'fdikit.svm')")
        self.data = dict(data)
        self.sv = np.asarray(data["support_vectors"], float)
        self.gamma = float(data["gamma"])
        self.classes = list(data["classes"])
        self.multiclass = "n_support" in data
        if self.multiclass:
            self.n_support = np.asarray(data["n_support"], int)
            self.coef = np.asarray(data["dual_coef"], float).reshape(len(self.classes) - 1, -1)
            self.b = np.asarray(data["intercept"], float).ravel()
            k = len(self.classes)
            if self.n_support.size != k or self.n_support.sum() != self.sv.shape[0] or \
                    self.b.size != k * (k - 1) // 2 or self.coef.shape[1] != self.sv.shape[0]:
                raise DataError(f"inconsistent multiclass SVM export: {k} classes, n_support "
                                f"{self.n_support.tolist()}, {self.sv.shape[0]} support vectors, "
                                f"dual_coef {self.coef.shape}, {self.b.size} intercepts")
        else:
            self.coef = np.asarray(data["dual_coef"], float)
            self.b = float(data["intercept"])

    def to_dict(self) -> dict[str, Any]:
        """The exported SVM (plain data; support vectors become an NPZ array in an artifact)."""
        out = dict(self.data)
        out["support_vectors"] = self.sv
        return out

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> SVMDecision:
        return cls(d)

    def features(self, X: Any) -> np.ndarray:
        X = np.asarray(getattr(X, "values", X), dtype=float)
        if X.ndim == 3:
            X = concat_measurements(X)
        f = self.data.get("features")
        if f is not None:
            X = WindowFeatures(f["n_channels"], f["window"], f["combination"]).transform(X)
        s = self.data.get("scaler")
        if s is not None:
            X = (X - np.asarray(s["mean"])) / np.asarray(s["scale"])
        if X.shape[1] != self.sv.shape[1]:
            raise DataError(f"patterns give {X.shape[1]} features, the SVM was trained on {self.sv.shape[1]}")
        return X

    def _kernel(self, X: Any) -> np.ndarray:
        Z = self.features(X)
        d2 = (np.sum(Z**2, 1)[:, None] + np.sum(self.sv**2, 1)[None, :] - 2.0 * Z @ self.sv.T)
        return np.exp(-self.gamma * np.maximum(d2, 0.0))

    def decision_function(self, X: Any) -> np.ndarray:
        """``f(y)`` of eq. (42) before the sign: (n,) for two classes; (n, n_pairs) one-vs-one values
        (pairs (0, 1), (0, 2), ..., positive = the first class of the pair) for more."""
        K = self._kernel(X)
        if not self.multiclass:
            return K @ self.coef + self.b  # luo-et-al eq. (42)
        k = len(self.classes)
        start = np.concatenate([[0], np.cumsum(self.n_support)])
        out = np.empty((K.shape[0], k * (k - 1) // 2))
        p = 0
        for a in range(k):
            for b in range(a + 1, k):
                sa, sb = slice(start[a], start[a + 1]), slice(start[b], start[b + 1])
                # libsvm: coefficients of class a's SVs in row b - 1, of class b's SVs in row a
                out[:, p] = K[:, sa] @ self.coef[b - 1, sa] + K[:, sb] @ self.coef[a, sb] + self.b[p]
                p += 1
        return out

    def predict(self, X: Any) -> np.ndarray:
        d = self.decision_function(X)
        if not self.multiclass:
            c0, c1 = np.array(self.classes[0], dtype=object), np.array(self.classes[1], dtype=object)
            return np.where(d > 0, c1, c0)
        k = len(self.classes)
        votes = np.zeros((d.shape[0], k), int)
        p = 0
        for a in range(k):
            for b in range(a + 1, k):
                win = d[:, p] > 0
                votes[:, a] += win
                votes[:, b] += ~win
                p += 1
        return np.array(self.classes, dtype=object)[np.argmax(votes, axis=1)]
