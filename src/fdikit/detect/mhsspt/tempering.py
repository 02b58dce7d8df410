"""Calibrated posteriors: a temperature on the MHSSPT's log-likelihoods fitted on held-out data
(:func:`fit_temperature`, :func:`design_calibrated_mhsspt`) and the reliability of posteriors
against the truth (:func:`reliability`: the table of confidence vs observed frequency and the
expected calibration error).

An MHSSPT multiplies per-sample likelihoods. Densities estimated from few samples of many
channels, a test run that differs from the training run and serial correlation the whitening
left make every factor too sharp, and the posterior goes to 1e-17 on fault-free data. Dividing
every log-likelihood by a temperature ``T > 1`` discounts each sample's evidence; ``T`` is chosen
on data the densities were not fitted on (time-blocked: the densities on the first part of every
record, the temperature on the rest), by the mean negative log posterior of the true hypothesis
(a proper score) or the expected calibration error.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ...errors import DataError
from ...signals import Signals
from .design import WhitenedMHSSPT, _segment_list, design_mhsspt
from .diagnosis import _fault_outputs
from .recursion import _mhsspt_recursion

__all__ = ["decision_outputs", "design_calibrated_mhsspt", "fit_temperature", "reliability"]


def reliability(posteriors, truth, bins: int = 10) -> dict:
    """Reliability of top-label posteriors: per bin of the largest posterior, how often its
    hypothesis is the true one, and the expected calibration error.

    Parameters
    ----------
    posteriors : array (..., K)
        Posterior of each of K exclusive decisions (e.g. no fault and every fault) per sample.
    truth : array (...) of int
        Index of the true decision per sample; negative: unlabelled, left out.
    bins : int
        Equal-width bins of the confidence on [0, 1] (the last one closed).

    Returns
    -------
    dict
        ``edges`` (bins + 1,), per bin ``count``, ``confidence`` (mean largest posterior) and
        ``frequency`` (fraction right; nan for an empty bin), ``ece`` (the count-weighted mean of
        ``|frequency - confidence|``), ``n`` (labelled samples) and ``table`` (the rows as text).

    Examples
    --------
    >>> P = np.array([[0.95, 0.05], [0.95, 0.05], [0.3, 0.7], [0.3, 0.7]])
    >>> r = reliability(P, np.array([0, 0, 1, 0]), bins=10)
    >>> r["count"][[6, 9]].tolist(), r["frequency"][[6, 9]].tolist(), round(r["ece"], 3)
    ([2, 2], [0.5, 1.0], 0.125)
    """
    P = np.asarray(posteriors, float)
    y = np.asarray(truth)
    if P.shape[:-1] != y.shape:
        raise DataError(f"truth shape {y.shape} does not match posteriors {P.shape} (..., K)")
    if int(bins) < 1:
        raise DataError(f"bins must be >= 1, got {bins}")
    P, y = P.reshape(-1, P.shape[-1]), y.reshape(-1).astype(int)
    if np.any(y >= P.shape[1]):
        raise DataError(f"truth index {int(y.max())} out of range for {P.shape[1]} decisions")
    keep = y >= 0
    P, y = P[keep], y[keep]
    conf = P.max(axis=1)
    right = P.argmax(axis=1) == y
    edges = np.linspace(0.0, 1.0, int(bins) + 1)
    b = np.clip(np.searchsorted(edges, conf, side="right") - 1, 0, int(bins) - 1)
    count = np.bincount(b, minlength=int(bins))
    with np.errstate(invalid="ignore", divide="ignore"):
        confidence = np.bincount(b, conf, minlength=int(bins)) / count
        frequency = np.bincount(b, right.astype(float), minlength=int(bins)) / count
    n = int(count.sum())
    ece = float(np.nansum(count * np.abs(frequency - confidence)) / n) if n else float("nan")
    rows = ["  bin          count  confidence  frequency"]
    for i in range(int(bins)):
        rows.append(f"  [{edges[i]:.2f}, {edges[i + 1]:.2f}) {count[i]:6d}  {confidence[i]:10.3f}  "
                    f"{frequency[i]:9.3f}")
    rows.append(f"  ECE {ece:.4f} over {n} samples")
    return {"edges": edges, "count": count, "confidence": confidence, "frequency": frequency,
            "ece": ece, "n": n, "table": "\n".join(rows)}


def decision_outputs(out: Signals) -> tuple[list[str], np.ndarray]:
    """The exclusive decisions of an MHSSPT output (the no-fault output, then every fault output,
    a group in place of its members, as :func:`~fdikit.detect.detection_time`) and their
    posteriors (runs, T, K)."""
    h0, names = _fault_outputs(out, None)
    cols = [h0, *names]
    return cols, out.values[:, :, out.index(cols)]


def _truth_index(truth, names: list[str], T: int, i: int) -> np.ndarray:
    y = np.asarray(truth)
    if y.shape != (T,):
        raise DataError(f"record {i}: truth must have one label per sample ({T}), got shape {y.shape}")
    if y.dtype.kind in "iu":
        return y.astype(int)
    lookup = {n: k for k, n in enumerate(names)} | {n[2:]: k for k, n in enumerate(names)}
    bad = [str(v) for v in np.unique(y) if str(v) not in lookup and v is not None]
    if bad:
        raise DataError(f"record {i}: unknown labels {bad}; decisions: {names}")
    return np.array([lookup.get(str(v), -1) if v is not None else -1 for v in y], int)


def _decisions(test: WhitenedMHSSPT, ll: np.ndarray, T: float, cols: list[int]) -> np.ndarray:
    """Posteriors of the decision columns for cached (temperature 1) log-likelihoods at temperature
    ``T``: the operations of ``test.run`` with ``test.temperature = T``."""
    test.reset(ll.shape[0])
    llT = ll if T == 1.0 else ll / T
    out = np.empty_like(llT)
    _mhsspt_recursion(np.ascontiguousarray(llT), test._logF, test._log1mp, test._logp_pi, test._logq,
                      test._log1mq, out)
    return test._outputs(out)[:, :, cols]


def fit_temperature(test: WhitenedMHSSPT, records: Sequence[Any], truths: Sequence[Any], *,
                    grid: Sequence[float] | None = None, score: str = "nll", bins: int = 10) -> dict:
    """Fit ``test.temperature`` on held-out labelled records (data its densities were not fitted on).

    Parameters
    ----------
    test : WhitenedMHSSPT
        The test; its ``temperature`` is set to the best one.
    records : sequence of arrays (T_i, C)
        Held-out contiguous records of the test's inputs (each from a reset).
    truths : sequence of arrays (T_i,)
        The true decision per sample: a decision output name (``"P:none"``, ``"P:<fault>"`` or
        without ``P:``) or its index in :func:`decision_outputs`; None or -1: unlabelled.
    grid : sequence of float, optional
        Temperatures tried (default 37 from 0.5 to 2000, geometric).
    score : {"nll", "ece"}
        Mean negative log posterior of the true decision (a proper score; default) or the
        expected calibration error of :func:`reliability`.
    bins : int
        Reliability bins.

    Returns
    -------
    dict
        ``temperature``, ``grid``, ``scores`` (per temperature), ``reliability`` at the chosen
        temperature (on these records) and ``decisions`` (the names).
    """
    if score not in ("nll", "ece"):
        raise DataError(f"score must be 'nll' or 'ece', got {score!r}")
    recs = _segment_list(list(records), "held-out", len(test.input_names))
    if len(truths) != len(recs):
        raise DataError(f"{len(recs)} records but {len(truths)} truths")
    grid = np.geomspace(0.5, 2000.0, 37) if grid is None else np.asarray(grid, float)
    if grid.ndim != 1 or grid.size == 0 or np.any(~(grid > 0)) or not np.all(np.isfinite(grid)):
        raise DataError("grid must be positive, finite temperatures")
    probe = Signals(np.arange(2.0), np.zeros((2, len(test.input_names))), test.input_names)
    saved = test.temperature
    test.temperature = 1.0
    try:
        names, _ = decision_outputs(test.run(probe))
        cols = [test.output_names.index(n) for n in names]
        lls, ys = [], []
        for i, (r, y) in enumerate(zip(recs, truths)):
            lls.append(np.ascontiguousarray(test.loglik(test.whitened(r[None]))))
            ys.append(_truth_index(y, names, r.shape[0], i))
        scores = []
        for T in grid:
            P = [_decisions(test, ll, float(T), cols)[0] for ll in lls]
            Pc, yc = np.concatenate(P), np.concatenate(ys)
            keep = yc >= 0
            if score == "nll":
                s = float(-np.mean(np.log(np.maximum(Pc[keep, yc[keep]], 1e-300))))
            else:
                s = reliability(Pc, yc, bins)["ece"]
            scores.append(s)
        best = float(grid[int(np.argmin(scores))])
        P = np.concatenate([_decisions(test, ll, best, cols)[0] for ll in lls])
        rel = reliability(P, np.concatenate(ys), bins)
    except BaseException:
        test.temperature = saved
        raise
    test.temperature = best
    test.reset(1)
    return {"temperature": best, "grid": grid, "scores": np.asarray(scores), "reliability": rel,
            "decisions": names}


def design_calibrated_mhsspt(
    inputs: Sequence[str],
    nominal,
    segments: Mapping[str, Any],
    p: float,
    *,
    holdout: float = 0.5,
    grid: Sequence[float] | None = None,
    score: str = "nll",
    **design,
) -> WhitenedMHSSPT:
    """:func:`design_mhsspt` with its temperature fitted on held-out data, time-blocked.

    Every nominal record and every fault segment is cut in time: the first ``1 - holdout`` of it
    designs the test (whitening, densities), the rest fits the temperature
    (:func:`fit_temperature`) on records made of each held-out nominal part alone and of the
    first held-out nominal part followed by each held-out fault part (a fault onset, as in use).

    Parameters
    ----------
    inputs, nominal, segments, p
        As :func:`design_mhsspt`.
    holdout : float
        Fraction (0 < holdout < 1) of every record held out for the temperature.
    grid, score
        As :func:`fit_temperature`.
    **design
        Passed to :func:`design_mhsspt` (``whiten``, ``order``, ``max_order``, ``criterion``,
        ``scale``, ``q``, ``no_fault``, ``cov``).

    Returns
    -------
    WhitenedMHSSPT
        With ``temperature`` set; ``tempering`` holds the :func:`fit_temperature` result.

    Examples
    --------
    >>> from scipy.signal import lfilter
    >>> rng = np.random.default_rng(0)
    >>> ar = lambda n: lfilter([1.0], [1.0, -0.9], rng.normal(size=(n, 2)), axis=0)
    >>> t = design_calibrated_mhsspt(["a", "b"], ar(8000), {"f": ar(2000) + [3.0, -3.0]}, p=1e-3)
    >>> bool(t.temperature > 0), t.tempering["decisions"]
    (True, ['P:none', 'P:f'])
    """
    if not 0 < holdout < 1:
        raise DataError(f"holdout must be in (0, 1), got {holdout}")
    C = len(inputs)

    def cut(r):
        k = round(r.shape[0] * (1 - holdout))
        return r[:k], r[k:]

    nom = [cut(r) for r in _segment_list(nominal, "nominal", C)]
    segs = {f: [cut(s) for s in _segment_list(v, f"fault {f!r}", C)] for f, v in segments.items()}
    test = design_mhsspt(inputs, [a for a, _ in nom], {f: [a for a, _ in v] for f, v in segs.items()}, p,
                         **design)
    no_fault = design.get("no_fault", "none")
    groups = {g: m for g, m in test.groups.items()}
    records, truths = [], []
    for _, b in nom:
        records.append(b)
        truths.append(np.full(b.shape[0], no_fault, object))
    lead = nom[0][1]
    for f, v in segs.items():
        names = [str(f)] if len(v) == 1 else [f"{f}:{i}" for i in range(len(v))]
        label = str(f) if (str(f) in groups or len(v) == 1) else names[0]
        for _, b in v:
            records.append(np.concatenate([lead, b]))
            truths.append(np.r_[np.full(lead.shape[0], no_fault, object), np.full(b.shape[0], label, object)])
    test.tempering = fit_temperature(test, records, truths, grid=grid, score=score)
    return test
