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
``diagnosis``   the diagnosis (:class:`fdikit.isolate.DMatrixDecision`): the D-matrix of the test
                set learned from ``dmatrix_runs`` Monte Carlo runs per fault class
                (:func:`~fdikit.systems.abs.campaign.run_campaign` with the designed tests), one
                decision per episode by maximum likelihood over the learned Pd/Pf, made once the
                fired tests have been stable for ``settle`` s
==============  ==============================================================================

The diagnosis is what the config monitor announces (``[decision] processor = "diagnosis"``): one
announcement per fault episode naming the fault class -- or the group of classes no outcome of
the tests can tell apart (``F1.1|F1.2``: every test fires for both) -- with its posterior
probability. Severity: the ABS classes are severity bins (F1.1 / F1.2 a wheel-speed sensor 2-5 %
/ >= 5 % low, F2.1 / F2.2 the wheel radius 2-20 % / >= 20 % smaller), so the class is the
severity estimate of the paper's test set; with ``tests = "extended"`` the size of an R_w, K_f or
I_w diagnosis is the amplitude estimate of the matching directional GLRT (``G_D_Rw:eta``, ...:
the relative parameter change). The output-error estimate of
:mod:`fdikit.systems.abs.estimation` needs the whole record and stays with
:class:`~fdikit.systems.abs.diagnoser.ABSDiagnoser`.

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

__all__ = ["PARAMS", "alarm_channel", "design", "diagnosis"]

#: Recipe parameters and their defaults.
PARAMS: dict[str, Any] = {
    "design_runs": 1000,   # nominal Monte Carlo runs for mu0, sigma^2 and the thresholds
    "snr_db": 23.0,        # process-noise level of the design runs (paper: 17, 20 or 23 dB)
    "pfa": 0.0,            # target per-run false-alarm probability of each test (0: none in the runs)
    "margin": 0.1,         # relative safety margin on each threshold
    "seed": 0,
    "dt": 0.01,            # measurement period (s), the paper's 100 Hz
    "tests": "paper",      # "paper": the five GLRT tests; "extended": plus the directional GLRTs
    "dmatrix_runs": 40,    # Monte Carlo runs per fault class that learn the D-matrix (0: no diagnosis)
    "settle": 1.0,         # s: the fired tests stable this long before the diagnosis is made
}

#: Directional test -> the fault classes whose size its amplitude estimate gives.
_SIZE_TESTS = {"G_D_Rw": ("F2.1", "F2.2"), "G_D_Kf": ("F3",), "G_D_Iw": ("F4",)}


def alarm_channel(spec) -> str:
    """The alarm channel of one test of the recipe's monitor (see the module docstring)."""
    if spec.signature is not None:
        return f"{spec.statistic_channel}:alarm"
    return f"{spec.residual}:glrt:alarm" + (":gated" if spec.gate is not None else "")


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
    out["_report"] = {"rates": "model-based", "claims": _claims(bank, p)}
    runs = int(p["dmatrix_runs"])
    if runs < 0:
        raise DataError(f"ABS recipe: dmatrix_runs must be >= 0, got {runs}")
    if runs:
        out["diagnosis"] = diagnosis(bank, runs=runs, settle=float(p["settle"]), dt=dt,
                                     snr_db=float(p["snr_db"]), seed=int(p["seed"]) + 1)
    return out


def _claims(bank, p: dict) -> list[dict]:
    """Per-run false-alarm claims of the designed tests (``fdikit validate``): each test's alarm
    channel with the Clopper-Pearson interval of the nominal design runs that alarmed at its
    threshold, their family (Bonferroni) and the announcements (at most the family's)."""
    from ...detect.rates import proportion_interval

    base = {"per": "run", "target": float(p["pfa"]), "basis": f"{int(p['design_runs'])} simulated nominal "
            "stops"}
    out, his, los = [], [], []
    for s in bank.specs:
        d = bank.design[s.name]
        k = round(float(d["achieved_pfa"]) * int(d["runs"]))
        lo, hi = proportion_interval(k, int(d["runs"]))
        if "shared_with" in d:   # a gate only removes alarms of the test it shares its threshold with
            lo = 0.0
        out.append({"name": f"test {s.name}", "kind": "threshold", "channels": [alarm_channel(s)],
                    "interval": [lo, hi], "method": f"{k} of {d['runs']} design runs alarmed", **base})
        his.append(hi)
        los.append(lo)
    fam = [max(los), min(1.0, sum(his))]
    out.append({"name": "family (any test)", "kind": "family", "channels": [c["channels"][0] for c in out],
                "interval": fam, "method": "Bonferroni over the tests", **base})
    out.append({"name": "decision (announcements)", "kind": "decision", "channels": [],
                "interval": [0.0, fam[1]], "method": "at most the family's", **base})
    return out


def diagnosis(bank, *, runs: int = 40, settle: float = 1.0, dt: float = 0.01, snr_db: float = 23.0,
              seed: int = 1):
    """The episode diagnosis of a designed ABS test bank: a :class:`fdikit.isolate.DMatrixDecision`
    on the D-matrix learned from ``runs`` Monte Carlo runs of every fault class (nominal included).

    Parameters
    ----------
    bank : TestBank
        The designed tests (:func:`~fdikit.systems.abs.campaign.design_tests`).
    runs : int
        Runs per fault class (and nominal runs) that learn the D-matrix.
    settle : float
        Seconds the fired tests must be stable before the decision.
    dt : float
        Sample time, s.
    snr_db : float
        Process-noise level of the learning runs.
    seed : int
        Seed of the learning runs (a stream apart from the design's).
    """
    from ...isolate import DMatrixDecision
    from .campaign import run_campaign

    if not (settle >= 0 and dt > 0):
        raise DataError(f"ABS recipe: settle must be >= 0 s and dt > 0 s, got {settle} and {dt}")
    dm = run_campaign(runs=runs, nominal_runs=runs, bank=bank, seed=seed, snr_db=snr_db).dmatrix
    spec = {s.name: s for s in bank.specs}
    inputs = [alarm_channel(spec[t]) for t in dm.tests]
    sizes = {c: f"{t}:eta" for t, classes in _SIZE_TESTS.items() if t in spec for c in classes}
    return DMatrixDecision(dm, inputs, nominal="F0", settle=round(settle / dt), sizes=sizes)
