"""SVM isolation tests S_Kf / S_Iw (paper luo-et-al, Section VI and Appendix A).

The K_f (brake torque gain) and I_w (wheel inertia) faults move the ABS residuals alike, so the
paper isolates them with a support vector machine trained on simulated records: each pattern is
the two measurements (wheel speed, vehicle speed; 1250 samples each) concatenated into one
vector of 2500 values (eq. (36)), the kernel is the RBF ``exp(-||y_i - y_j||^2 / (2 sigma^2))``
with ``sigma = 20`` and ``C = 1`` (eqs. (38)-(42)). With scikit-learn's ``SVC`` this is
``gamma = 1 / (2 sigma^2) = 1/800``.

Improvement (:func:`improved_pipeline`). The raw pattern is dominated by the vehicle speed
trajectory, whose random walk under process noise is common to both measurements and carries no
information on which parameter changed. The fault shows in the *slip speed* ``omega_v -
omega_w``, which the sliding-mode controller modulates; its mean over 500 ms windows (25
features) removes the common mode and averages out the measurement noise and the valve
chattering. ``C`` and ``gamma`` of the RBF SVC are chosen by stratified 5-fold cross-validation on
the training set only. A ``StandardScaler`` step is available (``scale=True``) but off by default:
all features share one unit (rad/s) and standardising inflates the windows after standstill,
where only measurement noise varies. Measured on two independent 720-pattern sets at 23 dB
(train on one, test on the other, both ways): window means of the slip speed 1 + 0 errors
unscaled, 3 + 0 standardised; 250 ms windows 2 + 1 / 8 + 2; both channels separately (no
difference) standardised 21 + 10. Against the paper's raw patterns (3 + 0) the gain shows when
the process noise grows: 20 dB, 180 + 180 patterns: 1 vs 6 errors; 17 dB, 720 + 720: 3 vs 15.
See :class:`WindowFeatures` (any linear channel combination, any window) for other plants.

:class:`SVMIsolator` wraps either pipeline for any labelled pattern set: ``fit``/``predict``,
the binary test outcomes ``S_<label>`` of the D-matrix, and :meth:`SVMIsolator.export`, a plain
data (JSON-able) form of the trained decision function (eq. (42)) that :class:`SVMDecision`
evaluates with numpy alone — no pickle.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.model_selection import GridSearchCV, StratifiedKFold
from sklearn.pipeline import Pipeline
from sklearn.preprocessing import StandardScaler
from sklearn.svm import SVC

from ..errors import DataError

__all__ = [
    "C_PAPER",
    "SIGMA_PAPER",
    "SVMDecision",
    "SVMIsolator",
    "WindowFeatures",
    "abs_patterns",
    "abs_svm_experiment",
    "concat_measurements",
    "improved_pipeline",
    "paper_pipeline",
    "rbf_gamma",
]

SIGMA_PAPER = 20.0  # RBF width sigma of Section VI
C_PAPER = 1.0  # box constraint C of eq. (38), Section VI
#: Magnitudes of the training/test grid of Section VI: ±2 %, ±3 %, ..., ±10 % (18 sizes).
SIZES = tuple(s * k / 100.0 for s in (-1, 1) for k in range(2, 11))


def rbf_gamma(sigma: float) -> float:
    """scikit-learn's ``gamma`` for the paper's RBF width: ``1 / (2 sigma^2)`` (Appendix A).

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

    def __init__(self, n_channels: int = 2, window: int = 50,
                 combination: Sequence[float] | None = (-1.0, 1.0)):
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


def paper_pipeline(sigma: float = SIGMA_PAPER, C: float = C_PAPER) -> Pipeline:
    """The paper's classifier: RBF SVC on the raw concatenated measurements (Section VI).

    Examples
    --------
    >>> from fdikit.isolate.svm import paper_pipeline
    >>> paper_pipeline().named_steps["svc"].gamma
    0.00125
    """
    return Pipeline([("svc", SVC(kernel="rbf", gamma=rbf_gamma(sigma), C=float(C)))])


def improved_pipeline(
    n_channels: int = 2,
    window: int = 50,
    combination: Sequence[float] | None = (-1.0, 1.0),
    *,
    scale: bool = False,
    Cs: Sequence[float] = (1.0, 10.0, 100.0, 1000.0),
    gammas: Sequence[Any] = ("scale", 3e-3, 1e-2, 3e-2, 0.1),
    cv: int = 5,
    random_state: int = 0,
) -> GridSearchCV:
    """Window features (-> StandardScaler) -> RBF SVC, with ``C`` and ``gamma`` cross-validated.

    Parameters
    ----------
    n_channels, window, combination
        See :class:`WindowFeatures` (default: 500 ms means of ``omega_v - omega_w``, in rad/s).
    scale : bool
        Insert a ``StandardScaler`` after the features (see the module docstring for why the
        default is off for the ABS).
    Cs, gammas : sequences
        Grid of the box constraint and of the RBF ``gamma`` (1/feature-unit^2; "scale" is
        scikit-learn's ``1 / (n_features · var(X))``).
    cv : int
        Folds of the stratified cross-validation (on the training data only).
    random_state : int
        Seed of the fold shuffling.

    Examples
    --------
    >>> from fdikit.isolate.svm import improved_pipeline
    >>> sorted(improved_pipeline().param_grid)
    ['svc__C', 'svc__gamma']
    """
    steps: list[tuple[str, Any]] = [("features", WindowFeatures(n_channels, window, combination))]
    if scale:
        steps.append(("scale", StandardScaler()))
    steps.append(("svc", SVC(kernel="rbf")))
    return GridSearchCV(Pipeline(steps), {"svc__C": list(Cs), "svc__gamma": list(gammas)},
                        cv=StratifiedKFold(int(cv), shuffle=True, random_state=random_state))


class SVMIsolator:
    """An SVM isolation test for any labelled pattern set (paper 2, Section VI).

    Parameters
    ----------
    pipeline : {"paper", "improved"} or sklearn estimator
        ``"paper"``: :func:`paper_pipeline`; ``"improved"``: :func:`improved_pipeline`; or any
        classifier with fit/predict (a Pipeline ending in an RBF ``SVC`` can be exported).
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
    >>> iso = SVMIsolator("paper").fit(X, lab)
    >>> iso.error(X, lab) < 0.1, sorted(iso.outcomes(X[:1]))
    (True, ['S_Iw', 'S_Kf'])
    """

    def __init__(self, pipeline: Any = "paper", test_names: Mapping[Any, str] | None = None):
        self.pipeline = pipeline
        self.test_names = dict(test_names or {})

    def _make(self) -> Any:
        from sklearn.base import clone

        if isinstance(self.pipeline, str):
            if self.pipeline == "paper":
                return paper_pipeline()
            if self.pipeline == "improved":
                return improved_pipeline()
            raise DataError(f"unknown pipeline {self.pipeline!r}; use 'paper', 'improved' or an estimator")
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
        t0 = time.perf_counter()
        est = self._make().fit(X, lab)
        self.fit_time_ = time.perf_counter() - t0
        self.search_ = est if isinstance(est, GridSearchCV) else None
        self.estimator_ = est.best_estimator_ if isinstance(est, GridSearchCV) else est
        self.classes_ = np.asarray(self.estimator_.classes_)
        return self

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
        ``b`` of eq. (42). Binary problems only.
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
        if len(svc.classes_) != 2:
            raise DataError(f"export handles two classes, got {len(svc.classes_)}")
        out.update({
            "classes": [c.item() if hasattr(c, "item") else c for c in svc.classes_],
            "gamma": float(svc._gamma),
            "support_vectors": svc.support_vectors_.tolist(),
            "dual_coef": svc.dual_coef_[0].tolist(),
            "intercept": float(svc.intercept_[0]),
        })
        return out


class SVMDecision:
    """Numpy evaluation of an exported SVM (eq. (42)): no scikit-learn, no pickle.

    ``f(y) = sum_i alpha_i z_i K(y, y_i) + b``; the pattern is of ``classes[1]`` when ``f > 0``.

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit.isolate.svm import SVMDecision, SVMIsolator
    >>> X = np.array([[0.0, 0.0], [0.1, 0.0], [3.0, 3.0], [3.1, 3.0]])
    >>> iso = SVMIsolator("paper").fit(X, ["a", "a", "b", "b"])
    >>> SVMDecision(iso.export()).predict(X).tolist()
    ['a', 'a', 'b', 'b']
    """

    def __init__(self, data: Mapping[str, Any]):
        if data.get("kind") != "fdikit.svm":
            raise DataError("not an exported fdikit SVM (kind != 'fdikit.svm')")
        self.data = dict(data)
        self.sv = np.asarray(data["support_vectors"], float)
        self.coef = np.asarray(data["dual_coef"], float)
        self.b = float(data["intercept"])
        self.gamma = float(data["gamma"])
        self.classes = list(data["classes"])

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

    def decision_function(self, X: Any) -> np.ndarray:
        """``f(y)`` of eq. (42) before the sign, (n,)."""
        Z = self.features(X)
        d2 = (np.sum(Z**2, 1)[:, None] + np.sum(self.sv**2, 1)[None, :] - 2.0 * Z @ self.sv.T)
        return np.exp(-self.gamma * np.maximum(d2, 0.0)) @ self.coef + self.b  # paper 2, eq. (42)

    def predict(self, X: Any) -> np.ndarray:
        d = self.decision_function(X)
        c0, c1 = np.array(self.classes[0], dtype=object), np.array(self.classes[1], dtype=object)
        return np.where(d > 0, c1, c0)


# --------------------------------------------------------------------------------------------
# The ABS data set of Section VI
# --------------------------------------------------------------------------------------------
def abs_patterns(
    per_size: int = 20,
    seed: int = 0,
    *,
    sizes: Sequence[float] = SIZES,
    faults: Mapping[str, str] | None = None,
    snr_db: float | None = 23.0,
    scenario: Any = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Simulated K_f / I_w patterns of Section VI: ``per_size`` records per fault size and fault.

    Parameters
    ----------
    per_size : int
        Records per (fault, size) (paper: 20, giving 20 x 18 x 2 = 720 patterns).
    seed : int
        Master seed; (fault, size) cell ``(a, b)`` uses ``SeedSequence(seed, spawn_key=(a, b))``,
        so two seeds give independent sets.
    sizes : sequence of float
        Relative fault sizes (paper: ±2 %, ..., ±10 %).
    faults : mapping label -> fault class
        Default ``{"K_f": "F3", "I_w": "F4"}``.
    snr_db : float or None
        Process noise (paper: 23 dB); measurement noise is the plant's 0.004.
    scenario : fdikit.plants.abs.Scenario, optional
        Manoeuvre (default 28 m/s, 12.5 s).

    Returns
    -------
    X : ndarray (n, 2·1250)
        Concatenated measurements (rad/s).
    labels : ndarray (n,) of str
    magnitudes : ndarray (n,)

    Examples
    --------
    >>> from fdikit.isolate.svm import abs_patterns
    >>> X, lab, mag = abs_patterns(per_size=1, sizes=(0.05,))
    >>> X.shape, lab.tolist(), mag.tolist()
    ((2, 2500), ['K_f', 'I_w'], [0.05, 0.05])
    """
    from dataclasses import replace

    from ..plants import abs as A

    faults = dict(faults or {"K_f": "F3", "I_w": "F4"})
    base = scenario if scenario is not None else A.Scenario()
    X, lab, mag = [], [], []
    for a, (label, fc) in enumerate(faults.items()):
        for b, m in enumerate(sizes):
            sc = replace(base, fault=fc, magnitude=float(m), snr_db=snr_db)
            s = int(np.random.SeedSequence(seed, spawn_key=(a, b)).generate_state(1)[0] & 0x7FFFFFFF)
            res = A.simulate(None, sc, runs=per_size, seed=s)
            X.append(concat_measurements(res.y.values))
            lab += [label] * per_size
            mag += [float(m)] * per_size
    return np.vstack(X), np.array(lab), np.array(mag)


def abs_svm_experiment(per_size: int = 20, train_seed: int = 1, test_seed: int = 2,
                       snr_db: float | None = 23.0) -> dict[str, Any]:
    """Section VI: train on ``per_size``·36 patterns, test on as many independent ones.

    Returns
    -------
    dict
        For ``"paper"`` and ``"improved"``: ``error`` (fraction), ``errors`` (count), ``n_test``,
        ``fit_time``, ``predict_time`` (s), ``n_support``; the improved one also ``best_params``
        and ``cv_error``, and ``fit_time_final`` (refit at the chosen hyper-parameters).

    Examples
    --------
    >>> from fdikit.isolate.svm import abs_svm_experiment
    >>> r = abs_svm_experiment(per_size=2)
    >>> r["paper"]["n_test"]
    72
    """
    Xtr, ztr, _ = abs_patterns(per_size, train_seed, snr_db=snr_db)
    Xte, zte, mte = abs_patterns(per_size, test_seed, snr_db=snr_db)
    out: dict[str, Any] = {"n_train": len(ztr)}
    for kind in ("paper", "improved"):
        iso = SVMIsolator(kind).fit(Xtr, ztr)
        t0 = time.perf_counter()
        pred = iso.predict(Xte)
        tp = time.perf_counter() - t0
        wrong = pred != zte
        svc = iso.estimator_[-1] if isinstance(iso.estimator_, Pipeline) else iso.estimator_
        r = {"error": float(np.mean(wrong)), "errors": int(wrong.sum()), "n_test": len(zte),
             "fit_time": iso.fit_time_, "predict_time": tp, "n_support": int(svc.n_support_.sum()),
             "wrong_magnitudes": sorted(mte[wrong].tolist())}
        if iso.search_ is not None:
            r["best_params"] = {k: (v if isinstance(v, str) else float(v))
                                for k, v in iso.search_.best_params_.items()}
            r["cv_error"] = float(1.0 - iso.search_.best_score_)
            from sklearn.base import clone

            t0 = time.perf_counter()
            clone(iso.estimator_).fit(Xtr, ztr)
            r["fit_time_final"] = time.perf_counter() - t0
        out[kind] = r
    return out
