"""The sections of a campaign in a report: Pd/Pf, the D-matrix, the confusion matrix,
sensitivity and specificity, detection-time histograms and ROC curves."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ..errors import DataError
from .html import Report, heatmap_figure
from .signature import add_signature

__all__ = ["add_campaign", "add_roc", "roc_curve"]


def roc_curve(nominal_scores, faulty_scores, n: int = 200) -> dict[str, list[float]]:
    """ROC of a threshold swept over a test's score (e.g. the largest statistic of each run).

    Parameters
    ----------
    nominal_scores, faulty_scores : array_like (runs,)
        The score of each fault-free and each faulty run; a run alarms when score > threshold.
    n : int
        Number of thresholds (quantiles of the pooled scores, plus the extremes).

    Returns
    -------
    dict
        ``threshold``, ``pf`` (fraction of nominal runs above it), ``pd`` (faulty runs above it),
        each a list from the highest threshold down, and ``auc`` (trapezoidal area).

    Examples
    --------
    >>> r = roc_curve([0.1, 0.2, 0.3], [0.25, 0.5, 0.9])
    >>> r["pf"][0], r["pd"][0], r["pf"][-1], r["pd"][-1], round(r["auc"], 3)
    (0.0, 0.0, 1.0, 1.0, 0.889)
    """
    a = np.asarray(nominal_scores, float).ravel()
    b = np.asarray(faulty_scores, float).ravel()
    if a.size == 0 or b.size == 0:
        raise DataError("roc_curve: needs at least one nominal and one faulty score")
    pooled = np.concatenate([a, b])
    thr = np.unique(
        np.concatenate([np.quantile(pooled, np.linspace(0, 1, n)), pooled if pooled.size <= n else []])
    )
    thr = np.concatenate([[np.inf], thr[::-1], [-np.inf]])
    pf = np.array([(a > x).mean() for x in thr])
    pd = np.array([(b > x).mean() for x in thr])
    auc = float(np.sum(np.diff(pf) * (pd[1:] + pd[:-1]) / 2))
    return {"threshold": thr.tolist(), "pf": pf.tolist(), "pd": pd.tolist(), "auc": auc}


def add_roc(rep: Report, curves: Mapping[str, Mapping[str, Sequence[float]]], *, title: str = "ROC") -> None:
    """ROC curves ``{name: {"pf": [...], "pd": [...], "auc"?: float}}`` (a threshold swept)."""
    data = [
        {
            "type": "scatter",
            "mode": "lines",
            "x": [0, 1],
            "y": [0, 1],
            "name": "chance",
            "line": {"dash": "dot", "color": "grey"},
        }
    ]
    for name, c in curves.items():
        lab = f"{name} (AUC {c['auc']:.3f})" if c.get("auc") is not None else name
        data.append(
            {
                "type": "scatter",
                "mode": "lines+markers",
                "x": list(c["pf"]),
                "y": list(c["pd"]),
                "name": lab,
                "marker": {"size": 4},
            }
        )
    rep.figure(
        {
            "data": data,
            "layout": {
                "title": {"text": title},
                "height": 460,
                "xaxis": {"title": {"text": "false-alarm probability Pf (–)"}, "range": [-0.02, 1.02]},
                "yaxis": {"title": {"text": "detection probability Pd (–)"}, "range": [-0.02, 1.02]},
            },
        }
    )


def add_campaign(rep: Report, c: Mapping[str, Any], *, where: str = "campaign") -> dict:
    """The sections of a campaign result (the JSON of ``fdikit abs campaign``).

    Recognised keys (each optional, at least one needed): ``pd`` {class: {test: Pd}}, ``pf``
    {test: Pf}, ``dmatrix`` {faults, tests, d, pd}, ``confusion`` {class: {label: count}},
    ``sensitivity``, ``sensitivity_exact``, ``specificity``, ``detection_rate``, ``tree``,
    ``detection_time_histogram`` {edges, counts {class: [...]}}, ``roc`` {test: {pf, pd}},
    ``complete`` (the complete diagnoser), ``tests`` {thresholds}, ``runs``, ``snr_db``.
    """
    if not isinstance(c, Mapping):
        raise DataError(f"{where}: a campaign must be a JSON object, got {type(c).__name__}")
    known = (
        "pd",
        "pf",
        "dmatrix",
        "confusion",
        "sensitivity",
        "specificity",
        "detection_time_histogram",
        "roc",
    )
    if not any(k in c for k in known):
        raise DataError(
            f"{where}: not a campaign result: none of the keys {list(known)} (keys: {sorted(c)[:12]})"
        )
    added = []
    meta = {k: c[k] for k in ("snr_db", "magnitudes", "runs", "wall_seconds", "engine") if k in c}
    if meta:
        rep.section("Campaign", "Monte Carlo evaluation of the tests and the diagnosis.")
        rep.table(meta)
        thr = (c.get("tests") or {}).get("thresholds") if isinstance(c.get("tests"), Mapping) else None
        if thr:
            rep.table([{"test": k, "threshold": v} for k, v in thr.items()], caption="designed thresholds")
    pd, pf = c.get("pd"), c.get("pf")
    if pd is not None or pf is not None:
        try:
            tests = list(pf) if pf else list(next(iter(pd.values())))
            classes = (["F0 (Pf)"] if pf else []) + [str(k) for k in (pd or {})]
            z = ([[float(pf[tn]) for tn in tests]] if pf else []) + [
                [float(pd[k].get(tn, np.nan)) for tn in tests] for k in (pd or {})
            ]
        except (AttributeError, KeyError, TypeError, ValueError, StopIteration) as exc:
            raise DataError(
                f"{where}: key 'pd' must be {{class: {{test: Pd}}}} and 'pf' {{test: Pf}} ({exc})"
            ) from None
        rep.section(
            "Pd and Pf per test and class",
            "Fraction of runs in which each test fired: Pf on the nominal class F0, Pd on each fault class.",
        )
        rep.figure(
            heatmap_figure(
                z,
                tests,
                classes,
                title="Pd / Pf per test and class",
                colorbar="probability (–)",
                zmin=0,
                zmax=1,
                x_title="test",
                y_title="class",
            )
        )
        rep.table(
            [{"class": cl, **{tn: v for tn, v in zip(tests, row)}} for cl, row in zip(classes, z)],
            caption="Pd / Pf",
        )
        added.append("pd_pf")
    dm = c.get("dmatrix")
    if isinstance(dm, Mapping) and "d" in dm:
        try:
            d = np.asarray(dm["d"], float)
            text = None
            if dm.get("pd") is not None:
                p = np.asarray(dm["pd"], float)
                text = [
                    [f"{int(d[i, j])} ({p[i, j]:.3f})" for j in range(d.shape[1])] for i in range(d.shape[0])
                ]
            add_signature(
                rep,
                {
                    "matrix": d,
                    "rows": dm["faults"],
                    "columns": dm["tests"],
                    "title": "D-matrix",
                    "text": text,
                    "colorbar": "test fires (0/1)",
                    "zmin": 0,
                    "zmax": 1,
                    "intro": "Learned D-matrix: 1 where the test fires for the fault (in brackets the "
                    "firing fraction)."
                    + (
                        f" Ambiguity groups: {dm.get('ambiguity_groups')}."
                        if dm.get("ambiguity_groups")
                        else ""
                    ),
                },
            )
        except (KeyError, TypeError, ValueError, IndexError) as exc:
            raise DataError(f"{where}: key 'dmatrix' must have faults, tests and d ({exc})") from None
        added.append("dmatrix")
    conf = c.get("confusion")
    if isinstance(conf, Mapping) and conf:
        true = list(conf)
        labels = list(dict.fromkeys([*true, *(lab for row in conf.values() for lab in row)]))
        counts = np.array([[float(conf[a].get(b, 0)) for b in labels] for a in true])
        frac = counts / np.maximum(counts.sum(axis=1, keepdims=True), 1)
        text = [
            [f"{int(counts[i, j])}" if counts[i, j] else "" for j in range(len(labels))]
            for i in range(len(true))
        ]
        rep.section(
            "Confusion matrix",
            "Diagnosed class (columns) of the runs of each true class (rows); colour: "
            "fraction of the row, text: number of runs.",
        )
        rep.figure(
            heatmap_figure(
                frac,
                labels,
                true,
                title="confusion matrix",
                colorbar="fraction of runs (–)",
                text=text,
                zmin=0,
                zmax=1,
                x_title="diagnosed",
                y_title="true class",
            )
        )
        added.append("confusion")
    rates = {k: c[k] for k in ("sensitivity", "sensitivity_exact", "specificity", "detection_rate") if k in c}
    tree = c.get("tree")
    if isinstance(tree, Mapping):
        rates.update({f"tree {k}": tree[k] for k in ("sensitivity", "specificity") if k in tree})
    comp = c.get("complete")
    if isinstance(comp, Mapping):
        rates.update(
            {
                f"complete {k}": comp[k]
                for k in ("sensitivity", "sensitivity_exact", "specificity", "svm_error")
                if k in comp
            }
        )
    if rates:
        rep.section(
            "Sensitivity and specificity",
            "Sensitivity: fraction of faulty runs diagnosed correctly; "
            "specificity: fraction of nominal runs diagnosed fault-free.",
        )
        rep.table(
            [{"measure": k, "value (%)": 100 * float(v) if v is not None else None} for k, v in rates.items()]
        )
        ref = c.get("paper_table_v")
        if isinstance(ref, Mapping) and ref:
            rep.table(
                [
                    {"SNR (dB)": k, "paper sensitivity (%)": v[0], "paper specificity (%)": v[1]}
                    for k, v in ref.items()
                ],
                caption="the paper's Table V",
            )
        added.append("rates")
    if isinstance(tree, Mapping) and tree.get("text"):
        rep.pre(tree["text"], summary="diagnostic tree (AO*)")
    if isinstance(comp, Mapping):
        if isinstance(comp.get("tree"), Mapping) and comp["tree"].get("listing"):
            rep.pre(comp["tree"]["listing"], summary="complete diagnoser tree")
        est = comp.get("estimation")
        if isinstance(est, Mapping) and est:
            rep.table(
                [
                    {"class": k, **{kk: vv for kk, vv in v.items() if not isinstance(vv, list | dict)}}
                    for k, v in est.items()
                ],
                caption="fault-size estimation",
            )
    hist = c.get("detection_time_histogram")
    if isinstance(hist, Mapping) and hist.get("counts"):
        try:
            edges = np.asarray(hist["edges"], float)
            centres = 0.5 * (edges[1:] + edges[:-1])
            data = [
                {
                    "type": "bar",
                    "x": centres.tolist(),
                    "y": list(map(float, v)),
                    "name": str(k),
                    "width": float(np.diff(edges).mean()) * 0.9,
                    "opacity": 0.7,
                }
                for k, v in hist["counts"].items()
            ]
        except (KeyError, TypeError, ValueError) as exc:
            raise DataError(
                f"{where}: key 'detection_time_histogram' must have edges and counts ({exc})"
            ) from None
        rep.section(
            "Detection times",
            "Histogram of the first-alarm times"
            + (f" of {hist['test']}" if hist.get("test") else " (G_P1 in the ABS campaign)")
            + " per class.",
        )
        rep.figure(
            {
                "data": data,
                "layout": {
                    "title": {"text": "detection-time histogram"},
                    "barmode": "overlay",
                    "height": 420,
                    "xaxis": {"title": {"text": "detection time (s)"}},
                    "yaxis": {"title": {"text": "runs (count)"}},
                },
            }
        )
        added.append("histogram")
    roc = c.get("roc")
    if isinstance(roc, Mapping) and roc:
        rep.section("ROC", "Detection against false-alarm probability as the threshold is swept.")
        add_roc(rep, roc)
        added.append("roc")
    rep.data.setdefault(
        "campaign", {k: c[k] for k in ("snr_db", "runs", "sensitivity", "specificity", "pd", "pf") if k in c}
    )
    return {"sections": added}

