"""Design recipe of the config-driven ABS monitor (``examples/abs/monitor.toml``).

``fdikit design examples/abs/monitor.toml`` calls :func:`design`, which calibrates the residuals
and designs the thresholds of the paper's five GLRT tests from nominal Monte Carlo runs of the ABS
plant (:func:`fdikit.systems.abs.campaign.design_tests`: thresholds for a target false-alarm
probability, never hand-tuned) and returns every stage as a design artifact:

==============  ==============================================================================
artifact        stage
==============  ==============================================================================
``r1``          parity residual r1, eq. (25) (:class:`~fdikit.systems.abs.residuals.ParityR1`)
``observer``    nonlinear observer residuals r3, r4, eqs. (29)-(33) (``ABSObserver``)
``glrt_rK``     moving-window GLRT of residual rK, eq. (24), with its calibrated mu0 and sigma^2
``hold_rK``     the alarm rule (34): the statistic above the designed threshold Z samples running
``gate_NAME``   the time gate (35) of the gated tests G_O_T1 / G_O_T2
``dglrt_NAME``  with ``tests = "extended"``: the directional GLRT of a test ``G_D_*``
                (:class:`~fdikit.detect.DirectionalGLRT`), and ``hold_NAME`` its alarm rule
==============  ==============================================================================

With ``tests = "extended"`` (:func:`fdikit.systems.abs.campaign.extended_tests`) the ``observer``
artifact is the observer with its parameter signatures
(:func:`~fdikit.systems.abs.residuals.observer_sensitivity`, a
:class:`~fdikit.residuals.ParameterSensitivity`) and the decision gains ``G_D_Iw:dglrt:alarm``,
``G_D_Kf:dglrt:alarm``, ``G_D_Rw:dglrt:alarm`` (``examples/abs/monitor_extended.toml``).

Decision channels (one per test of Table III): ``r1:glrt:alarm`` = G_P1, ``r3:glrt:alarm`` =
G_O1, ``r4:glrt:alarm`` = G_O2, ``r3:glrt:alarm:gated`` = G_O_T1, ``r4:glrt:alarm:gated`` =
G_O_T2. The diagnosis of a whole record (diagnostic tree, SVM, parameter estimate) needs the
complete record and is :class:`fdikit.systems.abs.diagnoser.ABSDiagnoser`, not a per-sample
stage.
"""

from __future__ import annotations

from typing import Any

from ...errors import DataError

__all__ = ["PARAMS", "design"]

#: Recipe parameters and their defaults.
PARAMS: dict[str, Any] = {
    "design_runs": 1000,   # nominal Monte Carlo runs for mu0, sigma^2 and the thresholds
    "snr_db": 23.0,        # process-noise level of the design runs (paper: 17, 20 or 23 dB)
    "pfa": 0.0,            # target per-run false-alarm probability of each test (0: none in the runs)
    "margin": 0.1,         # relative safety margin on each threshold
    "seed": 0,
    "dt": 0.01,            # measurement period (s), the paper's 100 Hz
    "tests": "paper",      # "paper": the five GLRT tests; "extended": plus the directional GLRTs
}


def design(params: dict[str, Any] | None = None) -> dict[str, Any]:
    """Design every stage of the ABS residual monitor (see the module docstring).

    Parameters
    ----------
    params : dict, optional
        Keys of :data:`PARAMS`; unknown keys are refused.

    Returns
    -------
    dict
        Artifact name -> design object (generators, GLRTs, holds, time gates).

    Examples
    --------
    >>> d = design({"design_runs": 20, "pfa": 0.1})       # doctest: +SKIP
    >>> sorted(d)[:3]                                    # doctest: +SKIP
    ['gate_G_O_T1', 'gate_G_O_T2', 'glrt_r1']
    """
    from ...detect import GLRT, Hold, TimeGated
    from .campaign import design_tests, residual_generators, test_set

    p = dict(PARAMS)
    for k, v in (params or {}).items():
        if k not in PARAMS:
            raise DataError(f"ABS recipe: unknown parameter {k!r}; known: {sorted(PARAMS)}")
        p[k] = v
    specs = test_set(str(p["tests"]))
    bank = design_tests(specs, design_runs=int(p["design_runs"]), snr_db=float(p["snr_db"]),
                        seed=int(p["seed"]), pfa=float(p["pfa"]), margin=float(p["margin"]))
    dt = float(p["dt"])
    r1, obs = residual_generators(specs, dt)
    out: dict[str, Any] = {"r1": r1, "observer": obs}
    for s in bank.specs:
        r = s.residual
        thr = bank.thresholds[s.name]
        if s.signature is not None:
            if s.gate is not None:
                raise DataError(f"test {s.name}: the recipe has no gated directional tests")
            out[f"dglrt_{s.name}"] = bank.processor(s)
            out[f"hold_{s.name}"] = Hold([s.statistic_channel], thr, s.Z, absolute=False)
        elif s.gate is None:
            if f"glrt_{r}" in out:
                raise DataError(f"test {s.name}: a second ungated test on residual {r}")
            out[f"glrt_{r}"] = GLRT([r], bank.mu0[r], bank.sigma2[r], s.W)
            out[f"hold_{r}"] = Hold([f"{r}:glrt"], thr, s.Z, absolute=False)
        else:
            base = out.get(f"hold_{r}")
            if base is None or float(base.threshold[0]) != thr or base.Z != s.Z:
                raise DataError(f"gated test {s.name} must share residual, window, hold and threshold "
                                f"with an ungated test on {r}")
            out[f"gate_{s.name}"] = TimeGated([f"{r}:glrt:alarm"], 0.5, s.gate)
    return out
