"""SVM isolation tests S_Kf / S_Iw (luo-et-al, Section VI and Appendix A).

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

The generic :class:`fdikit.isolate.SVMIsolator` runs either pipeline: ``fit``/``predict``,
the binary test outcomes ``S_<label>`` of the D-matrix, and :meth:`SVMIsolator.export`, a plain
data (JSON-able) form of the trained decision function (eq. (42)) that :class:`SVMDecision`
evaluates with numpy alone — no pickle.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from sklearn.model_selection import GridSearchCV
from sklearn.pipeline import Pipeline
from sklearn.svm import SVC

from ...errors import DataError
from ...isolate.svm import SVMIsolator, WindowFeatures, concat_measurements, cv_pipeline, rbf_gamma
from .plant import Scenario, simulate

__all__ = ["C_PAPER", "SIGMA_PAPER", "SIZES", "abs_patterns", "abs_pipeline", "abs_svm_experiment",
           "improved_pipeline", "paper_pipeline"]

SIGMA_PAPER = 20.0  # RBF width sigma of Section VI
C_PAPER = 1.0  # box constraint C of eq. (38), Section VI
#: Magnitudes of the training/test grid of Section VI: ±2 %, ±3 %, ..., ±10 % (18 sizes).
SIZES = tuple(s * k / 100.0 for s in (-1, 1) for k in range(2, 11))


def paper_pipeline(sigma: float = SIGMA_PAPER, C: float = C_PAPER) -> Pipeline:
    """The paper's classifier: RBF SVC on the raw concatenated measurements (Section VI).

    Examples
    --------
    >>> from fdikit.systems.abs.svm import paper_pipeline
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
    """Window features of the slip speed -> RBF SVC with ``C``/``gamma`` cross-validated
    (:func:`fdikit.isolate.svm.cv_pipeline` with :class:`~fdikit.isolate.svm.WindowFeatures`).

    Parameters
    ----------
    n_channels, window, combination
        See :class:`~fdikit.isolate.svm.WindowFeatures` (default: 500 ms means of
        ``omega_v - omega_w``, in rad/s).
    scale : bool
        Insert a ``StandardScaler`` after the features (off for the ABS: see the module docstring).
    Cs, gammas, cv, random_state
        See :func:`~fdikit.isolate.svm.cv_pipeline`. The folds are shuffled (``shuffle=True``): every
        pattern is an independent simulated run, so no pattern's neighbour leaks into validation.

    Examples
    --------
    >>> from fdikit.systems.abs.svm import improved_pipeline
    >>> sorted(improved_pipeline().param_grid)
    ['svc__C', 'svc__gamma']
    """
    return cv_pipeline(WindowFeatures(n_channels, window, combination), scale=scale, Cs=Cs, gammas=gammas,
                       cv=cv, random_state=random_state, shuffle=True)


def abs_pipeline(kind: Any) -> Any:
    """``"paper"`` -> :func:`paper_pipeline`, ``"improved"`` -> :func:`improved_pipeline`; an
    estimator is returned as it is."""
    if isinstance(kind, str):
        if kind == "paper":
            return paper_pipeline()
        if kind == "improved":
            return improved_pipeline()
        raise DataError(f"unknown ABS SVM pipeline {kind!r}; use 'paper', 'improved' or an estimator")
    return kind


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
    scenario : fdikit.systems.abs.Scenario, optional
        Manoeuvre (default 28 m/s, 12.5 s).

    Returns
    -------
    X : ndarray (n, 2·1250)
        Concatenated measurements (rad/s).
    labels : ndarray (n,) of str
    magnitudes : ndarray (n,)

    Examples
    --------
    >>> from fdikit.systems.abs.svm import abs_patterns
    >>> X, lab, mag = abs_patterns(per_size=1, sizes=(0.05,))
    >>> X.shape, lab.tolist(), mag.tolist()
    ((2, 2500), ['K_f', 'I_w'], [0.05, 0.05])
    """
    from dataclasses import replace

    faults = dict(faults or {"K_f": "F3", "I_w": "F4"})
    base = scenario if scenario is not None else Scenario()
    X, lab, mag = [], [], []
    for a, (label, fc) in enumerate(faults.items()):
        for b, m in enumerate(sizes):
            sc = replace(base, fault=fc, magnitude=float(m), snr_db=snr_db)
            s = int(np.random.SeedSequence(seed, spawn_key=(a, b)).generate_state(1)[0] & 0x7FFFFFFF)
            res = simulate(None, sc, runs=per_size, seed=s)
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
    >>> from fdikit.systems.abs.svm import abs_svm_experiment
    >>> r = abs_svm_experiment(per_size=2)
    >>> r["paper"]["n_test"]
    72
    """
    Xtr, ztr, _ = abs_patterns(per_size, train_seed, snr_db=snr_db)
    Xte, zte, mte = abs_patterns(per_size, test_seed, snr_db=snr_db)
    out: dict[str, Any] = {"n_train": len(ztr)}
    for kind in ("paper", "improved"):
        iso = SVMIsolator(abs_pipeline(kind)).fit(Xtr, ztr)
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
