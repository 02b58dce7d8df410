"""The complete ABS diagnoser (luo-et-al, Sections VI-VIII, Figs. 4-5 and 14).

Chain: residuals r1, r3, r4 -> five GLRT tests with designed thresholds (:mod:`fdikit.systems.abs.campaign`)
-> the optimal diagnostic tree of the learned D-matrix extended with the SVM tests S_Kf / S_Iw
-> the SVM, run only when the tree requests S_Kf or S_Iw -> severity estimate of the isolated
parameter by subset output-error estimation (:func:`fdikit.estimate.output_error`).

The tree (:func:`abs_tree`)
---------------------------
Rows: the eight fault states F0..F5 of Table II. Columns: the five GLRT tests and the two SVM
tests, all learned from Monte Carlo runs of every class (:func:`learn_dmatrix`). The SVM tests are
*gated*: S_Kf fires when a GLRT test has fired and the SVM says "K_f" (S_Iw alike), following
Section VI ("once the fault is detected, the SVM method be used"); without the gate the SVM,
which answers "K_f" or "I_w" for any record, would fire on half of the nominal runs. Their
Pd/Pf are thus learned on fresh records (independent seeds from the SVM's training patterns);
the pattern error of Section VI is reported separately (:func:`svm_rates`). A test enters a
fault's signature when it fires in more than ``level`` = 10 % of that class's runs (see
:func:`learn_dmatrix`). Priors are the paper's (P(F0) = 0.93, 0.01 per fault), costs 1 per
test; AO* on the binary matrix (perfect-test model, as TEAMS did for Fig. 14).
:func:`extend_with_svm` builds the same columns by definition for a given matrix: on Table IV
it gives Fig. 14's Go-path (G_O1), its redundant test (S_Iw) and the expected cost 1.21 of the
paper's own listing (tested; AO* orders G_P1 before G_O_T1, an equal-cost alternative).

**The learned tree and its differences from Fig. 14** (23 dB, zero-false-alarm thresholds,
200 runs per class, magnitudes drawn in each class; ``complete_campaign(200)``)::

    IF G_O1 == G DISPLAY("SYSTEM OK or tau_m fault (>= 15 %)");
    ELSE REQUEST G_P1 TEST;
        IF G_P1 == G REQUEST S_Kf TEST;
            IF S_Kf == G DISPLAY("I_w fault");
            ELSE DISPLAY("K_f fault");
        ELSE REQUEST G_O_T1 TEST;
            IF G_O_T1 == G DISPLAY("sensor fault (< 5 %) or sensor fault (>= 5 %)");
            ELSE DISPLAY("R_w fault (< 20 %) or R_w fault (>= 20 %)");

Same as the paper: Go-path = {G_O1} alone; S_Iw redundant; S_Kf separates I_w from K_f after
G_O1 fails. Redundant here as well: G_O2 and G_O_T2 (expected cost 1.12 vs 1.21). Why: the
learned matrix is not Table IV (see :mod:`fdikit.systems.abs.campaign`). (i) G_P1 fires for both
sensor classes and both R_w classes, so F1.1/F1.2 and F2.1/F2.2 are ambiguity groups of the
tests — the paper needs G_O_T2 and G_O2 to split them, we cannot, and the diagnoser splits them
by the severity estimate instead (estimated k_ws or R_w change against Table II's class ranges:
F1.1 2-5 %, F1.2 >= 5 %; F2.1 2-20 %, F2.2 >= 20 %). (ii) The sensor fault shows from the first
sample and the R_w fault only after braking, so the gated G_O_T1 tells R_w from sensor faults
(one test where the paper uses G_O_T1, G_O_T2, G_O2). (iii) tau_m faults of +15..+50 % trigger no
GLRT test in this plant: F5 shares the "system OK" leaf. Measured with the same runs (observer with
the held output injection of eq. (32), :class:`fdikit.systems.abs.residuals.ABSObserver`): complete
tree sensitivity 74.6 % up to the leaf groups (22.4 % exact leaf), specificity 100 % (400 nominal
runs); full diagnoser (with the estimate splitting the groups) 74.3 % exact on 10 runs per faulty
class; SVM error 0.14 % (1 of 720 fresh patterns, improved pipeline); the unreliable-test tree on
the learned Pd/Pf (misdiagnosis cost 100) 66.4 % / 100 %, Go-path G_O1. (Before the held injection:
67.5 %, 15.3 %, 100 %, 68.6 %, 60.0 %.) Table V's 99.9 % is out of reach because F5 is undetected and
the small I_w faults drawn in their class do not fire G_O1 (F4: 79 of 200 runs missed; I_w changes
fire it from about ±6 %, Pd 0.55-0.74 there and 1.0 from ±8 %, 23 dB).
Subset estimation (oracle isolation, 20 runs per class, mean relative error): k_ws 0.24 / 0.13 %
(F1.1 / F1.2), R_w 0.13 / 0.13 %, K_f 0.19 %, I_w 0.84 %, tau_m 38 % (not identifiable under
23 dB process noise, see :mod:`fdikit.estimate.output_error`); Table VI's subset column: K_f 1.05,
I_w 0.52, tau_m 2.0, R_w 0.004 %.

With the extended test set (:func:`fdikit.systems.abs.campaign.extended_tests`; ``fdikit abs campaign
--tests extended --complete``), Table V setting (minimum sizes, W = 40, 23 dB, pfa 1e-4 per test,
10000 design runs, 1000 runs per class for the D-matrix): the learned tree's Go-path becomes
G_D_Iw (it fires for every class but F5), the tree reaches 81.3 % up to its leaf groups
(specificity 100 %), and the full diagnoser (tree, SVM, severity estimate splitting the sensor
leaf) 75.2 % exact on 60 runs per class: F1.1 60/60, F1.2 33/60 (at exactly -5 % it sits on the
class boundary, 27 runs estimated just above it), F2.1 51/60, F2.2 60/60, F3 60/60, F4 52/60,
F5 0/60 (undetectable, :mod:`fdikit.systems.abs.detectability`).

Monitor
-------
:meth:`ABSDiagnoser.monitor` is a :class:`fdikit.monitor.Monitor` with the two residual
generators and the test bank as processors (GLRT -> hold -> time gate); its alarm outputs equal
:meth:`TestBank.alarms` (tested). The tree, the SVM and the estimation are a decision stage run at
the *end* of a record, not per sample: the SVM and the output-error fit need the whole record
(the paper runs them offline, Section VII), so they are not a per-sample ``Decision``.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ...detect.bank import TestBank
from ...errors import DataError
from ...signals import Signals
from .campaign import abs_residuals, design_tests, paper_tests, residual_generators

__all__ = [
    "ESTIMATED_PARAM",
    "PAPER_PRIOR",
    "SVM_TESTS",
    "ABSDiagnoser",
    "abs_tree",
    "abs_tree_report",
    "complete_campaign",
    "demo_summary",
    "extend_with_svm",
    "learn_dmatrix",
    "svm_outcomes",
    "svm_rates",
]

#: Prior probabilities of Section VII (Fig. 14): system OK 0.93, each fault class 0.01.
PAPER_PRIOR = {"F0": 0.93, "F1.1": 0.01, "F1.2": 0.01, "F2.1": 0.01, "F2.2": 0.01, "F3": 0.01, "F4": 0.01,
               "F5": 0.01}
#: SVM test -> (SVM label, fault class it detects).
SVM_TESTS = {"S_Kf": ("K_f", "F3"), "S_Iw": ("I_w", "F4")}
#: Parameter estimated (subset selection, Section VIII) for each fault class.
ESTIMATED_PARAM = {"F1.1": "k_ws", "F1.2": "k_ws", "F2.1": "R_w", "F2.2": "R_w", "F3": "K_f", "F4": "I_w",
                   "F5": "tau_m"}
#: Search bounds of the subset estimate relative to the nominal value (hold every class of Table II).
_BOUNDS_REL = {"k_ws": (0.8, 1.05), "R_w": (0.6, 1.1), "K_f": (0.8, 1.2), "I_w": (0.8, 1.2),
               "tau_m": (0.5, 2.0)}
_LABELS = {"F0": "SYSTEM OK", "F1.1": "sensor fault (< 5 %)", "F1.2": "sensor fault (>= 5 %)",
           "F2.1": "R_w fault (< 20 %)", "F2.2": "R_w fault (>= 20 %)", "F3": "K_f fault", "F4": "I_w fault",
           "F5": "tau_m fault (>= 15 %)"}


# --------------------------------------------------------------------------------------------
# The tree
# --------------------------------------------------------------------------------------------
def svm_rates(iso, per_size: int = 10, seed: int = 2, snr_db: float | None = 23.0) -> dict[str, Any]:
    """Firing rates of S_Kf / S_Iw on fresh Section VI patterns (K_f and I_w faults, ±2..10 %).

    Returns
    -------
    dict
        ``rate[test][class]``: fraction of the class's patterns for which the test fires (Pd on its
        own class, Pf on the other); ``error`` (misclassified fraction), ``n`` patterns.
    """
    from .svm import abs_patterns

    X, lab, _ = abs_patterns(per_size, seed, snr_db=snr_db)
    pred = iso.predict(X)
    rate = {t: {fc: float(np.mean(pred[lab == other] == label)) for other, fc in
                (("K_f", "F3"), ("I_w", "F4"))} for t, (label, _) in SVM_TESTS.items()}
    return {"rate": rate, "error": float(np.mean(pred != lab)), "n": int(lab.size)}


def svm_outcomes(fired: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """Outcomes of S_Kf / S_Iw: the SVM's answer, given only once a GLRT test has fired.

    Parameters
    ----------
    fired : bool (runs, n_glrt)
    labels : (runs,) SVM labels ``"K_f"`` / ``"I_w"``

    Returns
    -------
    bool (runs, 2)
        Columns in the order of :data:`SVM_TESTS`; all False in runs where no GLRT test fired
        (Section VI: "once the fault is detected, the SVM method be used").

    Examples
    --------
    >>> import numpy as np
    >>> svm_outcomes(np.array([[1, 0], [0, 0]], bool), np.array(["K_f", "I_w"])).tolist()
    [[True, False], [False, False]]
    """
    det = np.asarray(fired, bool).any(axis=1)
    lab = np.asarray(labels)
    if lab.shape != det.shape:
        raise DataError(f"{det.size} runs of GLRT outcomes but {lab.size} SVM labels")
    return np.stack([det & (lab == lb) for lb, _ in SVM_TESTS.values()], axis=1)


def learn_dmatrix(fired: Mapping[str, np.ndarray], labels: Mapping[str, np.ndarray], tests, *,
                  level: float = 0.1):
    """D-matrix of the five GLRT tests and S_Kf / S_Iw learned from Monte Carlo runs of every class.

    ``d_ij = 1`` iff test ``j`` fires in more than ``level`` of the runs of class ``i``
    (:meth:`DMatrix.from_outcomes`). The default 0.1 instead of a majority: with the
    zero-false-alarm thresholds (Pf = 0 measured) a test that fires in 10 % of a class's runs
    responds to that fault; a majority rule would call the I_w class undetectable because only
    its larger negative changes (about -6 % and beyond) trigger G_O1.

    Returns
    -------
    DMatrix
        Columns ``tests`` + S_Kf, S_Iw; pd learned per (class, test), pf from the nominal runs.
    """
    from ...isolate import DMatrix

    out = {c: np.hstack([np.asarray(fired[c], bool), svm_outcomes(fired[c], labels[c])]) for c in fired}
    return DMatrix.from_outcomes(out, [*tests, *SVM_TESTS], nominal="F0", level=level)


def extend_with_svm(dm, rates: Mapping[str, Mapping[str, float]] | None = None):
    """The GLRT D-matrix extended with the columns S_Kf and S_Iw (module docstring).

    Parameters
    ----------
    dm : DMatrix
        Learned GLRT matrix with rows F0..F5.
    rates : mapping test -> {class: firing fraction}, optional
        From :func:`svm_rates`; default a perfect SVM.

    Returns
    -------
    DMatrix
        ``n_f x (n_t + 2)``; pd/pf of the GLRT columns as in ``dm``.

    Examples
    --------
    >>> from fdikit.isolate import DMatrix
    >>> dm = DMatrix(["F0", "F3", "F4"], ["G"], [[0], [1], [1]])
    >>> extend_with_svm(dm).d.astype(int).tolist()
    [[0, 0, 0], [1, 1, 0], [1, 0, 1]]
    """
    from ...isolate import DMatrix

    nf = len(dm.faults)
    d = np.zeros((nf, 2), bool)
    pd = np.ones((nf, 2))
    pf = np.zeros((nf, 2))
    for j, (t, (_, fc)) in enumerate(SVM_TESTS.items()):
        if fc not in dm.faults:
            raise DataError(f"the D-matrix has no row {fc!r} for SVM test {t}; rows {dm.faults}")
        d[dm.faults.index(fc), j] = True
        if rates is not None:
            for c, r in rates[t].items():
                i = dm.faults.index(c)
                (pd if c == fc else pf)[i, j] = float(r)
    dpd = np.where(dm.d, dm.pd, 1.0)
    return DMatrix(dm.faults, [*dm.tests, *SVM_TESTS], np.hstack([dm.d, d]),
                   pd=np.hstack([dpd, pd]), pf=np.hstack([dm.pf, pf]))


def abs_tree(dm, prior: Mapping[str, float] | None = None, cost=None, *, tests_model: str = "perfect",
             misdiagnosis_cost: float = 100.0):
    """AO* diagnostic tree of an extended ABS D-matrix, paper's priors and unit costs.

    ``tests_model="perfect"`` (default, Fig. 14) uses the binary matrix; ``"unreliable"`` uses
    the learned Pd/Pf of every (fault, test) pair with Bayes-updated beliefs and stops when a
    further test costs more than ``misdiagnosis_cost`` times the error it removes
    (:func:`fdikit.isolate.ao_star`).

    Examples
    --------
    >>> from fdikit.systems.abs.campaign import PAPER_TABLE_IV
    >>> from fdikit.isolate import DMatrix
    >>> dm = extend_with_svm(DMatrix(list(PAPER_TABLE_IV), ["G_P1", "G_O1", "G_O2", "G_O_T1", "G_O_T2"],
    ...                              list(PAPER_TABLE_IV.values())))
    >>> abs_tree(dm).go_path
    ['G_O1']
    """
    from ...isolate import DMatrix, ao_star

    prior = dict(PAPER_PRIOR if prior is None else prior)
    missing = [f for f in dm.faults if f not in prior]
    if missing:
        raise DataError(f"no prior probability for fault states {missing}")
    p = np.array([prior[f] for f in dm.faults], float)
    if tests_model == "perfect":
        return ao_star(DMatrix(dm.faults, dm.tests, dm.d), prior=p / p.sum(), cost=cost,
                       tests_model="perfect")
    if tests_model == "unreliable":
        return ao_star(dm, prior=p / p.sum(), cost=cost, tests_model="unreliable",
                       misdiagnosis_cost=misdiagnosis_cost)
    raise DataError(f"tests_model must be 'perfect' or 'unreliable', got {tests_model!r}")


def abs_tree_report(tree) -> dict[str, Any]:
    """Tree text, IF-THEN-ELSE listing, Go-path and redundant tests, next to Fig. 14's."""
    from ...isolate import to_listing

    return {"text": tree.to_text(), "listing": to_listing(tree, _LABELS), "go_path": tree.go_path,
            "redundant": tree.redundant_tests, "expected_cost": tree.expected_cost, "depth": tree.depth,
            "ambiguity_groups": tree.ambiguity_groups,
            "paper": {"go_path": ["G_O1"], "redundant": ["S_Iw"]}}


# --------------------------------------------------------------------------------------------
# Records
# --------------------------------------------------------------------------------------------
def _record(record) -> tuple[Signals, Any]:
    """(Signals with omega_w, omega_v, P_m, u_in, u_out; scenario or None) of an ABSResult/Signals."""
    if hasattr(record, "y") and hasattr(record, "u"):
        return record.y.concat_channels(record.u), getattr(record, "scenario", None)
    if isinstance(record, Signals):
        need = ["omega_w", "omega_v", "P_m", "u_in", "u_out"]
        missing = [n for n in need if n not in record.names]
        if missing:
            raise DataError(f"ABS record lacks channels {missing}; has {record.names}")
        return record.select(need), None
    raise DataError(f"expected an ABSResult or Signals, got {type(record).__name__}")


def _simulate_class(fault, magnitude, runs, seed, snr_db, scenario=None):
    """Measurements+inputs of ``runs`` runs of one class (same seeds/magnitudes as run_campaign)."""
    from .plant import FAULT_CLASSES, Scenario, simulate

    fc = FAULT_CLASSES[fault]
    base = scenario if scenario is not None else Scenario()
    if magnitude is not None and fc.symmetric:
        half = runs // 2
        parts = []
        for sign, first, n in ((1.0, 0, half), (-1.0, half, runs - half)):
            if n:
                sc = replace(base, fault=fault, magnitude=sign * abs(magnitude), snr_db=snr_db)
                r = simulate(None, sc, runs=n, seed=seed, first_run=first)
                parts.append((r.y.concat_channels(r.u), r.params.get(fc.param) if fc.param else None))
        sig = Signals(parts[0][0].t, np.concatenate([p[0].values for p in parts]), parts[0][0].names,
                      check=False)
        par = (None if fc.param is None
               else np.concatenate([np.broadcast_to(p[1], (p[0].runs,)) for p in parts]))
        return sig, par
    sc = replace(base, fault=fault, magnitude=magnitude, snr_db=snr_db,
                 grid_step=0.01 if fc.symmetric else None)
    r = simulate(None, sc, runs=runs, seed=seed)
    par = None if fc.param is None else np.broadcast_to(r.params[fc.param], (runs,)).astype(float)
    return r.y.concat_channels(r.u), par


# --------------------------------------------------------------------------------------------
# The diagnoser
# --------------------------------------------------------------------------------------------
@dataclass
class ABSDiagnoser:
    """Residuals -> GLRT tests -> diagnostic tree -> SVM on request -> severity estimate.

    Attributes
    ----------
    bank : TestBank
        The designed GLRT tests.
    dmatrix : DMatrix
        Learned GLRT matrix extended with S_Kf / S_Iw (:func:`extend_with_svm`).
    tree : DiagnosticTree
    svm : SVMIsolator
        Classifier with labels ``"K_f"``, ``"I_w"``.
    scenario : Scenario
        The manoeuvre re-simulated by the estimator when a record does not carry its own.
    info : dict
        Design figures (times, SVM error, runs).

    Examples
    --------
    >>> from fdikit.systems.abs.plant import Scenario, simulate
    >>> dg = ABSDiagnoser.design(design_runs=60, runs=10, svm_per_size=2)
    >>> out = dg.diagnose(simulate(None, Scenario(fault="F2.2", magnitude=-0.25), seed=7))
    >>> out["fault"], abs(out["relative_change"] + 0.25) < 0.02
    ('F2.2', True)
    """

    bank: TestBank
    dmatrix: Any
    tree: Any
    svm: Any
    scenario: Any = None
    info: dict = field(default_factory=dict)
    estimate: bool = True
    scan: int = 11

    # ---------------------------------------------------------------- design
    @classmethod
    def design(cls, *, design_runs: int = 200, runs: int = 30, svm_per_size: int = 5,
               snr_db: float | None = 23.0, seed: int = 0, svm: str = "improved",
               prior: Mapping[str, float] | None = None,
               bank: TestBank | None = None, level: float = 0.1) -> ABSDiagnoser:
        """Design everything from simulation: thresholds, D-matrix, SVM, tree.

        Parameters
        ----------
        design_runs : int
            Nominal runs of the threshold design (zero-false-alarm design, :func:`design_tests`).
        runs : int
            Runs per fault class (magnitudes drawn in each class) to learn the D-matrix.
        svm_per_size : int
            SVM training patterns per (fault, size); the paper's 20 gives 720 patterns. The SVM
            rates of the D-matrix use as many fresh patterns (another seed).
        svm : {"improved", "paper"}
            SVM pipeline (:class:`fdikit.isolate.SVMIsolator`).
        prior : mapping, optional
            Fault priors of the tree (default :data:`PAPER_PRIOR`).
        level : float
            Firing fraction above which a test enters a fault's signature (:func:`learn_dmatrix`).
        """
        from ...isolate.svm import SVMIsolator
        from .plant import FAULT_CLASSES
        from .svm import abs_patterns, abs_pipeline

        t0 = time.perf_counter()
        if bank is None:
            bank = design_tests(paper_tests(), design_runs=design_runs, snr_db=snr_db, seed=seed)
        t_design = time.perf_counter() - t0
        X, lab, _ = abs_patterns(svm_per_size, seed + 1, snr_db=snr_db)
        iso = SVMIsolator(abs_pipeline(svm)).fit(X, lab)
        rates = svm_rates(iso, svm_per_size, seed + 2, snr_db)
        fired, labels = {}, {}
        gens = residual_generators(bank.specs)
        for ci, c in enumerate(FAULT_CLASSES):
            sig, _ = _simulate_class(c, None, runs if c != "F0" else 2 * runs, seed + 7919 * ci, snr_db)
            fired[c] = bank.alarms(abs_residuals(sig, gens))[0]
            labels[c] = iso.predict(sig.select(["omega_w", "omega_v"]).values)
        dm = learn_dmatrix(fired, labels, bank.names, level=level)
        tree = abs_tree(dm, prior)
        info = {"design_seconds": t_design, "total_seconds": time.perf_counter() - t0,
                "svm_error": rates["error"],
                "svm_rates": rates["rate"], "runs": runs, "design_runs": design_runs, "snr_db": snr_db}
        return cls(bank, dm, tree, iso, info=info)

    # ---------------------------------------------------------------- monitor
    def monitor(self, dt: float = 0.01):
        """The online part as a :class:`fdikit.monitor.Monitor`: generators + GLRT/hold/gate processors.

        Returns
        -------
        Monitor, dict test -> alarm channel
        """
        from ...detect import Hold, TimeGated
        from ...monitor import Decision, Monitor

        procs, chan, made = [], {}, {}
        for s in self.bank.specs:
            key = (s.residual, s.W, s.Z, s.signature, s.nuisance, self.bank.thresholds[s.name])
            if key not in made:
                if any(k[0] == s.residual and k[3:5] == (s.signature, s.nuisance) for k in made):
                    raise DataError(f"test {s.name}: two ungated tests on residual {s.residual} with "
                                    "different settings cannot share one Monitor channel; use "
                                    "TestBank.alarms")
                procs.append(self.bank.processor(s))
                procs.append(Hold([s.statistic_channel], self.bank.thresholds[s.name], s.Z, absolute=False))
                made[key] = f"{s.statistic_channel}:alarm"
            if s.gate is None:
                chan[s.name] = made[key]
            else:
                procs.append(TimeGated([made[key]], 0.5, s.gate))
                chan[s.name] = f"{made[key]}:gated"
        dec = Decision(list(chan.values()), names={v: k for k, v in chan.items()})
        return Monitor(list(residual_generators(self.bank.specs, dt)), procs, dec), chan

    # ---------------------------------------------------------------- diagnosis
    def outcomes(self, record) -> tuple[np.ndarray, np.ndarray]:
        """GLRT outcomes (runs, 5) and first alarm times (s, NaN if none) of a record."""
        sig, _ = _record(record)
        return self.bank.alarms(abs_residuals(sig, residual_generators(self.bank.specs)))

    def estimate_param(self, y: np.ndarray, param: str, scenario=None) -> dict[str, float]:
        """Subset output-error estimate of one parameter from one record's measurements (T, 2)."""
        from ...estimate import output_error
        from .estimation import ABSSimulator

        sim = ABSSimulator(scenario if scenario is not None else self.scenario)
        nom = sim.params[param]
        lo, hi = _BOUNDS_REL[param]
        r = output_error(sim, y, [param], bounds={param: (nom * lo, nom * hi)}, scan=self.scan,
                         diff_step=1e-3)
        th = float(r.theta[param])
        return {"param": param, "nominal": float(nom), "estimate": th, "relative_change": th / nom - 1.0,
                "seconds": float(r.elapsed)}

    def diagnose(self, record, run: int = 0) -> dict[str, Any]:
        """Diagnose one run of a record.

        Parameters
        ----------
        record : ABSResult or Signals
            ``omega_w``, ``omega_v`` (rad/s), ``P_m``, ``u_in``, ``u_out``; 12.5 s at 10 ms for the
            SVM (its patterns have that length).
        run : int
            Which run of the record.

        Returns
        -------
        dict
            ``fault`` (class name, ``"F0"`` for system OK; a tuple-joined group if unresolved),
            ``leaf`` (the tree's leaf group), ``path`` (tests requested, with outcome), ``fired``
            {test: first alarm time in s} of the GLRT tests that fired, ``svm`` (label or None),
            ``param``, ``estimate``, ``relative_change`` (None when no parametric fault), ``seconds``.
        """
        from .plant import FAULT_CLASSES

        t0 = time.perf_counter()
        sig, sc = _record(record)
        if not 0 <= run < sig.runs:
            raise DataError(f"run {run} out of range: the record has {sig.runs} runs")
        one = Signals(sig.t, sig.values[run:run + 1], sig.names, check=False)
        fired, first = self.bank.alarms(abs_residuals(one, residual_generators(self.bank.specs)))
        names = self.bank.names
        out_glrt = dict(zip(names, fired[0].tolist()))
        svm_label = {}
        path = []

        def get(test):
            if test in SVM_TESTS and not fired[0].any():
                val = False  # the SVM answers only after a detection (svm_outcomes)
            elif test in SVM_TESTS:
                if "label" not in svm_label:
                    svm_label["label"] = str(self.svm.predict(one.select(["omega_w", "omega_v"]).values)[0])
                val = svm_label["label"] == SVM_TESTS[test][0]
            else:
                val = bool(out_glrt[test])
            path.append((test, "NG" if val else "G"))
            return val

        leaf = self.tree.diagnose(get)
        res: dict[str, Any] = {
            "leaf": list(leaf), "path": path,
            "fired": {n: float(first[0, j]) for j, n in enumerate(names) if fired[0, j]},
            "svm": svm_label.get("label"), "param": None, "estimate": None, "relative_change": None}
        if "F0" in leaf:
            res["fault"] = "F0"
        else:
            params = {ESTIMATED_PARAM[f] for f in leaf}
            fault = leaf[0] if len(leaf) == 1 else "|".join(leaf)
            if self.estimate and len(params) == 1:
                est = self.estimate_param(one.select(["omega_w", "omega_v"]).values[0], params.pop(), sc)
                res.update(param=est["param"], estimate=est["estimate"], nominal=est["nominal"],
                           relative_change=est["relative_change"])
                if len(leaf) > 1:  # resolve by the class ranges of Table II (closest class)
                    rc = est["relative_change"]

                    def dist(f):
                        fc = FAULT_CLASSES[f]
                        a = abs(rc) if fc.symmetric else rc
                        return max(fc.lo - a, a - fc.hi, 0.0)

                    fault = min(leaf, key=dist)
            res["fault"] = fault
        res["seconds"] = time.perf_counter() - t0
        return res


# --------------------------------------------------------------------------------------------
# Campaign of the complete tree
# --------------------------------------------------------------------------------------------
def complete_campaign(runs: int = 200, *, nominal_runs: int | None = None, bank: TestBank | None = None,
                      design_runs: int | None = None, snr_db: float | None = 23.0, seed: int = 0,
                      magnitudes: str = "draw", svm_per_size: int = 20, svm: str = "improved",
                      estimate_runs: int = 10, scan: int = 11, level: float = 0.1,
                      misdiagnosis_cost: float = 100.0) -> dict[str, Any]:
    """Sensitivity/specificity of the complete tree (GLRT + SVM tests), SVM error, estimation errors.

    The GLRT D-matrix is learned from the same runs (seeds of :func:`run_campaign`), extended
    with S_Kf/S_Iw from an SVM trained on ``svm_per_size``·36 Section VI patterns and rated on as
    many fresh ones (``svm_error``); the AO* tree with the paper's priors walks each run's
    outcomes, calling the SVM when requested. Sensitivity: faulty runs whose leaf contains the
    class and not F0 (``sensitivity``), or equals it (``sensitivity_exact``); specificity:
    nominal runs ending in the F0 leaf (Section VII). Estimation: for the first ``estimate_runs``
    runs of each parametric class, the subset estimate of the class's parameter (isolation taken
    as correct, as in Table VI), mean relative error ``|theta_hat - theta| / theta`` in percent.
    ``tree_unreliable``: the same for the AO* tree with the learned Pd/Pf (unreliable tests,
    misdiagnosis cost ``misdiagnosis_cost``, leaves = maximum-posterior class).
    ``diagnoser``: the complete :class:`ABSDiagnoser` (tree, SVM, and the severity estimate that
    splits the F1.1/F1.2 and F2.1/F2.2 leaves by the class ranges) on the same runs, its exact
    sensitivity and confusion.

    Returns
    -------
    dict

    Examples
    --------
    >>> out = complete_campaign(4, design_runs=20, svm_per_size=1, estimate_runs=1, scan=0)
    >>> 0.0 <= out["sensitivity"] <= 1.0 and "F3" in out["estimation"]
    True
    """
    from ...isolate.svm import SVMIsolator
    from .campaign import min_magnitudes
    from .plant import FAULT_CLASSES
    from .svm import abs_patterns, abs_pipeline

    t0 = time.perf_counter()
    nominal_runs = 2 * runs if nominal_runs is None else int(nominal_runs)
    design_runs = nominal_runs if design_runs is None else int(design_runs)
    if bank is None:
        bank = design_tests(paper_tests(), design_runs=design_runs, snr_db=snr_db, seed=seed)
    mags = min_magnitudes() if magnitudes == "min" else dict.fromkeys(FAULT_CLASSES)
    X, lab, _ = abs_patterns(svm_per_size, seed + 1, snr_db=snr_db)
    iso = SVMIsolator(abs_pipeline(svm)).fit(X, lab)
    rates = svm_rates(iso, svm_per_size, seed + 2, snr_db)
    fired, label, sigs, truth = {}, {}, {}, {}
    gens = residual_generators(bank.specs)
    for ci, c in enumerate(FAULT_CLASSES):
        n = nominal_runs if c == "F0" else runs
        sig, par = _simulate_class(c, mags[c], n, seed + 7919 * ci, snr_db)
        fired[c] = bank.alarms(abs_residuals(sig, gens))[0]
        label[c] = iso.predict(sig.select(["omega_w", "omega_v"]).values)
        sigs[c], truth[c] = sig, par
    dm = learn_dmatrix(fired, label, bank.names, level=level)
    tree = abs_tree(dm)
    names = dm.tests
    ok = exact = nf = 0
    spec = float("nan")
    confusion = {}
    rows = {c: np.hstack([fired[c], svm_outcomes(fired[c], label[c])]) for c in FAULT_CLASSES}
    utree = abs_tree(dm, tests_model="unreliable", misdiagnosis_cost=misdiagnosis_cost)
    u_ok = u_n = 0
    u_spec = float("nan")
    for c in FAULT_CLASSES:
        ul = [utree.diagnose(dict(zip(names, r.tolist()))) for r in rows[c]]
        if c == "F0":
            u_spec = float(np.mean(["F0" in g for g in ul]))
        else:
            u_ok += sum(c in g and "F0" not in g for g in ul)
            u_n += len(ul)
    for c in FAULT_CLASSES:
        leaves = [tree.diagnose(dict(zip(names, r.tolist()))) for r in rows[c]]
        keys = ["|".join(g) for g in leaves]
        confusion[c] = {str(k): int(v) for k, v in zip(*np.unique(keys, return_counts=True))}
        if c == "F0":
            spec = float(np.mean(["F0" in g for g in leaves]))
            continue
        ok += sum(c in g and "F0" not in g for g in leaves)
        exact += sum(g == (c,) for g in leaves)
        nf += len(leaves)
    dg = ABSDiagnoser(bank, dm, tree, iso, scan=scan)
    est = {}
    for c, param in ESTIMATED_PARAM.items():
        m = min(estimate_runs, sigs[c].runs)
        if m < 1:
            continue
        errs, secs, dchg = [], [], []
        for k in range(m):
            e = dg.estimate_param(sigs[c].select(["omega_w", "omega_v"]).values[k], param)
            th = float(truth[c][k])
            errs.append(abs(e["estimate"] - th) / th * 100.0)
            dchg.append(abs(e["relative_change"] - (th / e["nominal"] - 1.0)) * 100.0)
            secs.append(e["seconds"])
        est[c] = {"param": param, "runs": m, "mean_relative_error_pct": float(np.mean(errs)),
                  "max_relative_error_pct": float(np.max(errs)), "mean_change_error_pp": float(np.mean(dchg)),
                  "seconds_mean": float(np.mean(secs))}
    # the full diagnoser (tree + SVM + estimate resolving the F1.x / F2.x groups) on the same subset
    full_ok = full_n = 0
    full_conf: dict[str, dict[str, int]] = {}
    for c in FAULT_CLASSES:
        m = min(estimate_runs, sigs[c].runs)
        got = [dg.diagnose(sigs[c], k)["fault"] for k in range(m)]
        full_conf[c] = {str(k): int(v) for k, v in zip(*np.unique(got, return_counts=True))} if got else {}
        if c != "F0":
            full_ok += sum(g == c for g in got)
            full_n += m
    return {"sensitivity": ok / nf, "sensitivity_exact": exact / nf, "specificity": spec,
            "diagnoser": {"sensitivity_exact": full_ok / full_n if full_n else float("nan"),
                          "runs_per_class": int(estimate_runs), "confusion": full_conf},
            "svm_error": rates["error"], "svm_rates": rates["rate"], "svm_test_patterns": rates["n"],
            "tree_unreliable": {"sensitivity": u_ok / u_n, "specificity": u_spec,
                                "misdiagnosis_cost": misdiagnosis_cost, "go_path": utree.go_path,
                                "redundant": utree.redundant_tests, **utree.evaluate()},
            "dmatrix": {"faults": dm.faults, "tests": dm.tests, "d": dm.d.astype(int).tolist()},
            "tree": abs_tree_report(tree), "confusion": confusion, "estimation": est,
            "runs": {c: int(fired[c].shape[0]) for c in fired}, "wall_seconds": time.perf_counter() - t0}


# --------------------------------------------------------------------------------------------
# demo
# --------------------------------------------------------------------------------------------
_DEMO_CACHE: dict[str, ABSDiagnoser] = {}


def demo_summary(details: dict | None = None) -> dict[str, Any]:
    """Design a small diagnoser (cached in memory) and diagnose one record of each detectable class.

    ``details``, when given, receives ``diagnoser`` and ``records`` (the simulated record of each
    case, in the order of ``cases``), for the demo's report.

    Returns
    -------
    dict
        ``tree`` (Go-path, redundant tests, listing), ``svm_error``, ``cases``: injected fault and
        magnitude -> diagnosed fault, tests fired and severity estimate; ``seconds``.
    """
    from .plant import Scenario, simulate

    t0 = time.perf_counter()
    if "dg" not in _DEMO_CACHE:
        _DEMO_CACHE["dg"] = ABSDiagnoser.design(design_runs=100, runs=16, svm_per_size=3, seed=0)
    dg = _DEMO_CACHE["dg"]
    cases, records = [], []
    for f, m in (("F0", None), ("F1.2", -0.08), ("F2.2", -0.25), ("F3", -0.08), ("F4", -0.08)):
        rec = simulate(None, Scenario(fault=f, magnitude=m), seed=2026)
        records.append(rec)
        d = dg.diagnose(rec)
        cases.append({"injected": f, "magnitude": m, "diagnosed": d["fault"], "fired": d["fired"],
                      "param": d["param"], "relative_change": d["relative_change"]})
    if details is not None:
        details.update(diagnoser=dg, records=records)
    rep = abs_tree_report(dg.tree)
    return {"go_path": rep["go_path"], "redundant": rep["redundant"], "listing": rep["listing"],
            "svm_error": dg.info["svm_error"], "cases": cases, "seconds": time.perf_counter() - t0}
