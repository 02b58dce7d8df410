"""A linear two-mass spring-damper plant with position sensors: the small example system of the
demo and of ``examples/two-mass`` (the config-driven monitor).

States x1, v1 (mass 1), x2, v2 (mass 2); input force on mass 1; sensors pos1 and pos2 with
sensor faults declared. The design recipe :func:`design` makes an observer residual generator,
thresholds for a target false-alarm probability from nominal Monte Carlo runs, and the hold
rule -- everything a monitor needs, as saveable artifacts.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..detect import Hold, design_threshold
from ..faults import Noise, Scenario
from ..model import LinearFaultModel
from ..residuals import ObserverDesign, ObserverResidual, design_observer_residual

__all__ = ["DT", "NOISE_STD", "design", "model", "record", "scenario"]

#: Sample time (s) and measurement-noise standard deviation (m) of the example.
DT = 0.01
#: Measurement-noise standard deviation (m) of the example.
NOISE_STD = 0.002


def model() -> LinearFaultModel:
    """The continuous-time plant with faults ``sensor:pos1`` and ``sensor:pos2``."""
    A = [[0, 1, 0, 0], [-2, -0.4, 1, 0], [0, 0, 0, 1], [1, 0, -1, -0.3]]
    return LinearFaultModel(A, [[0], [1], [0], [0]], [[1, 0, 0, 0], [0, 0, 1, 0]],
                            states=["x1", "v1", "x2", "v2"], inputs=["force"], outputs=["pos1", "pos2"],
                            faults=["sensor:pos1", "sensor:pos2"], name="two-mass")


def force(t: Any) -> np.ndarray:
    """The excitation force (N): a slow sine."""
    return np.sin(0.7 * np.asarray(t))


def scenario(faults=(), duration: float = 10.0) -> Scenario:
    """Simulation scenario: sampled at :data:`DT`, measurement noise :data:`NOISE_STD`."""
    return Scenario(faults=list(faults), duration=duration, dt=DT, inputs=force,
                    noise=Noise(measurement=[NOISE_STD**2] * 2))


def record(faults=(), runs: int = 1, seed: int = 0, duration: float = 10.0):
    """Simulated records with the force and both sensors, as one :class:`~fdikit.Signals`."""
    from ..sim import simulate

    res = simulate(model(), scenario(faults, duration), runs=runs, seed=seed, keep=("y", "u"))
    return res.u.concat_channels(res.y)


def design(params: dict | None = None) -> dict[str, Any]:
    """Design recipe: ``{"observer": ObserverDesign, "hold": Hold}``, and under ``"_report"`` the
    false-alarm claims (``fdikit validate``): per threshold, per family (either sensor) and per
    announcement, the per-run probability with its interval from the nominal runs.

    ``params``: ``pfa`` (per-run false-alarm probability, default 1e-3), ``Z`` (hold, default
    5), ``runs`` (nominal runs for the thresholds, default 300), ``seed`` (default 0).
    """
    p = {"pfa": 1e-3, "Z": 5, "runs": 300, "seed": 0, **(params or {})}
    plant = model()
    obs: ObserverDesign = design_observer_residual(plant, dt=DT, Q=np.eye(4) * 1e-8,
                                                   R=np.eye(2) * NOISE_STD**2)
    gen = ObserverResidual(obs)
    r_nom = gen.run(record((), int(p["runs"]), int(p["seed"])))
    tds = [design_threshold(r_nom[name][:, 100:], float(p["pfa"]), Z=int(p["Z"]), absolute=True,
                            margin=0.05, min_events=0.0)
           for name in gen.output_names]
    thr = [td.threshold for td in tds]
    hold = Hold(gen.output_names, thr, Z=int(p["Z"]))
    return {"observer": obs, "hold": hold,
            "_report": {"rates": "model-based", "claims": _claims(hold.output_names, tds, p)}}


def _claims(alarms: list[str], tds: list, p: dict) -> list[dict]:
    """Per-run claims of the thresholds ``tds`` (one per alarm channel), their family (Bonferroni:
    between the largest lower and the sum of the upper bounds) and the announcements (at most the
    family's)."""
    ci = [[float(v) for v in td.ci] for td in tds]
    base = {"per": "run", "basis": f"{int(p['runs'])} simulated nominal runs", "hold": int(p["Z"])}
    out = [{"name": f"threshold {a.removesuffix(':alarm')}", "kind": "threshold", "channels": [a],
            "target": float(p["pfa"]), "interval": c, "method": td.method, **base}
           for a, c, td in zip(alarms, ci, tds)]
    fam = [max(c[0] for c in ci), min(1.0, sum(c[1] for c in ci))]
    out.append({"name": "family (any threshold)", "kind": "family", "channels": list(alarms),
                "target": float(p["pfa"]), "interval": fam, "method": "Bonferroni over the thresholds",
                **base})
    out.append({"name": "decision (announcements)", "kind": "decision", "channels": [],
                "target": float(p["pfa"]), "interval": [0.0, fam[1]], "method": "at most the family's",
                **base})
    return out
