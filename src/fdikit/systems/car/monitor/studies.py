"""Studies of the car monitor on the nonlinear car: the residual pattern table of ng-chen-speyer
Fig. 2 (:func:`pattern_table`) and detection and isolation of every fault at every calibration
magnitude on fresh noise (:func:`isolation_study`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ....detect.features import FeatureNorms
from ....faults import Bias
from ....monitor import Monitor
from ..driving import simulate_drive
from .calibration import calibrate_monitor
from .design import design_car_monitor
from .generators import _generators
from .settings import LATERAL_FAULTS, LONGITUDINAL_FAULTS, MAGNITUDES, car_signals, sensor_noise

__all__ = ["isolation_study", "pattern_table"]


def pattern_table(speed: float = 20.0, *, kind: str = "straight", duration: float = 6.0, onset: float = 2.0,
                  threshold: float = 3.0, seed: int = 3) -> dict[str, Any]:
    """Residual pattern table (ng-chen-speyer, Fig. 2) computed on the nonlinear car.

    Every fault of :data:`LONGITUDINAL_FAULTS` and :data:`LATERAL_FAULTS` is simulated at the middle
    of its calibration magnitudes (throttle actuator and sensor both); a residual "responds"
    (1) when the mean of its feature after ``onset + 1`` s exceeds the nominal mean by more than
    ``threshold`` nominal standard deviations and by 10 % of the largest response in its row.

    Returns
    -------
    dict
        ``columns`` (feature names), ``rows`` {fault: [0/1, ...]}, ``ratio`` {fault: [response /
        nominal std, ...]}, ``distinct`` (every binary row distinct and non-zero), ``max_cosine``
        and ``closest_pair`` (largest cosine between two hypotheses' graded rows), ``text``.
    """
    des = design_car_monitor(speed)
    faults = {**{k: v for k, v in LONGITUDINAL_FAULTS.items()}, "throttle_actuator": "actuator:throttle",
              **LATERAL_FAULTS}
    names = list(faults)
    R = 1 + len(names)
    bias = []
    for i, n in enumerate(names, start=1):
        mags = np.zeros(R)
        mags[i] = MAGNITUDES[faults[n]][1]
        bias.append(Bias(faults[n], mags, start=onset))
    res = simulate_drive(kind, speed, duration=duration, faults=bias, runs=R, seed=seed, dt=2.5e-3,
                         noise=sensor_noise())
    sig = car_signals(res)
    cols, X = [], []
    for block in ("longitudinal", "lateral"):
        gens, groups = _generators(des, block)
        st = Monitor(gens, [FeatureNorms(groups, des.dt, 0.03)]).run(sig).statistics
        cols += st.names
        X.append(st.values)
    X = np.concatenate(X, axis=2)
    t = sig.t
    nom = X[0, (t >= 1.0)]
    mu0, sd0 = nom.mean(0), np.maximum(nom.std(0), 1e-12)
    rows, ratio = {}, {}
    for i, n in enumerate(names, start=1):
        d = X[i, t >= onset + 1.0].mean(0) - mu0
        z = d / sd0
        rows[n] = [int(z[j] > threshold and d[j] > 0.1 * d.max()) for j in range(len(cols))]
        ratio[n] = z.round(1).tolist()
    keys = [tuple(v) for v in rows.values()]
    # throttle actuator and sensor share a hypothesis (paper IV-D): compare the hypotheses' rows
    hyp_rows = {n: tuple(v) for n, v in rows.items() if n != "throttle_actuator"}
    distinct = len(set(hyp_rows.values())) == len(hyp_rows) and all(any(v) for v in hyp_rows.values())
    # graded patterns (what the MHSSPT densities see): unit vectors of the positive z-scores; the
    # largest cosine between two hypotheses' rows
    hyp = [n for n in names if n != "throttle_actuator"]
    Z = np.array([np.clip(ratio[n], 0.0, None) for n in hyp])
    Zn = Z / np.maximum(np.linalg.norm(Z, axis=1, keepdims=True), 1e-300)
    cos = Zn @ Zn.T - 2 * np.eye(len(hyp))
    i, j = np.unravel_index(np.argmax(cos), cos.shape)
    short = [c.strip("|").replace("sensor:", "").replace("actuator:", "") for c in cols]
    w = max(len(n) for n in names)
    lines = [" " * w + " | " + " ".join(f"{j:>2d}" for j in range(len(cols)))]
    lines += [f"{n:<{w}} | " + " ".join(f"{'X' if v else '.':>2s}" for v in rows[n]) for n in names]
    lines += ["columns: " + ", ".join(f"{j}={c}" for j, c in enumerate(short))]
    del keys
    return {"columns": cols, "rows": rows, "ratio": ratio, "distinct": bool(distinct),
            "max_cosine": float(cos[i, j]), "closest_pair": [hyp[i], hyp[j]],
            "throttle_actuator_equals_sensor": rows["throttle_actuator"] == rows["throttle"],
            "text": "\n".join(lines)}


def isolation_study(block: str = "longitudinal", speed: float = 20.0, *, kind: str = "curve",
                    onset: float = 6.0, duration: float = 10.0, seed: int = 5, **cal_kw) -> dict[str, Any]:
    """Detection and isolation of every fault at every calibration magnitude, on fresh noise.

    One vectorised simulation (a nominal run and one run per fault and magnitude of
    :data:`MAGNITUDES`, noise seed ``seed`` different from the calibration's) through the
    calibrated monitor (:func:`calibrate_monitor` with ``cal_kw``). A run is *isolated* when at the
    end its fault's probability is >= 0.95, every other fault's <= 0.05 and no other fault was
    announced after the warm-up.

    Returns
    -------
    dict
        ``runs``: per fault and magnitude ``{isolated, delay_s, final_own, final_max_other,
        wrong}``; ``smallest_isolated``: per fault the smallest magnitude isolated (None if none);
        ``nominal_wrong`` and ``nominal_max_probability`` for the nominal run.
    """
    mon = calibrate_monitor(block, speed, kind=kind, **cal_kw)
    table = LONGITUDINAL_FAULTS if block == "longitudinal" else LATERAL_FAULTS
    runs = [("nominal", None, 0.0)] + [(name, f, m) for name, f in table.items() for m in MAGNITUDES[f]]
    R = len(runs)
    faults = []
    for f in dict.fromkeys(r[1] for r in runs[1:]):
        mags = np.array([r[2] if r[1] == f else 0.0 for r in runs])
        faults.append(Bias(f, mags, start=onset))
    res = simulate_drive(kind, speed, duration=duration, faults=faults, runs=R, seed=seed, dt=2.5e-3,
                         noise=sensor_noise())
    sig = car_signals(res)
    out = mon.run(sig)
    t = sig.t
    P = np.stack([out.statistics[f"P:{f}"] for f in mon.faults], axis=-1)  # (R, T, F)
    report: dict[str, Any] = {"runs": {}, "smallest_isolated": {}}
    for i, (name, _f, m) in enumerate(runs):
        ev = [e for e in out.events if e.run == i]
        if name == "nominal":
            report["nominal_wrong"] = [(round(e.t, 3), e.hypothesis) for e in ev]
            report["nominal_max_probability"] = round(float(P[i].max()), 4)
            continue
        j = mon.faults.index(name)
        others = [k for k in range(len(mon.faults)) if k != j]
        wrong = [(round(e.t, 3), e.hypothesis) for e in ev if e.hypothesis != name]
        own = np.flatnonzero((t >= onset) & (P[i, :, j] >= 0.95))
        iso = bool(P[i, -1, j] >= 0.95 and P[i, -1, others].max() <= 0.05 and not wrong)
        report["runs"].setdefault(name, {})[str(m)] = {
            "isolated": iso, "delay_s": round(float(t[own[0]] - onset), 3) if own.size else None,
            "final_own": round(float(P[i, -1, j]), 4),
            "final_max_other": round(float(P[i, -1, others].max()), 4),
            "wrong": wrong}
    for name, by in report["runs"].items():
        ok = [float(m) for m, r in by.items() if r["isolated"]]
        report["smallest_isolated"][name] = min(ok) if ok else None
    return report
