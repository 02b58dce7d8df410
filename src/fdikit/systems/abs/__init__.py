"""The ABS integrated diagnosis of luo-et-al: the nonlinear antilock braking plant under
sliding-mode PWM control with its fault universe F1-F5 (:mod:`.plant`), the parity and
nonlinear-observer residuals r1-r4 (:mod:`.residuals`), the GLRT test sets and the Monte Carlo
campaign of Tables III-V (:mod:`.campaign`), the complete diagnoser (tree, SVM, severity
estimation; :mod:`.diagnoser`), the SVM data set of Section VI (:mod:`.svm`), output-error
estimation of Table VI (:mod:`.estimation`), the Neyman-Pearson bounds of its faults
(:mod:`.detectability`) and the monitor config recipe (:mod:`.recipe`).
"""

from .campaign import (
    CampaignResult,
    abs_residuals,
    design_tests,
    extended_tests,
    min_magnitudes,
    paper_tests,
    residual_generators,
    run_campaign,
    test_set,
)
from .plant import FAULT_CLASSES, PARAMS, ABSPlant, ABSResult, FaultClass, Scenario, simulate
from .residuals import ABSObserver, ParityR1, ParityR2, observer_sensitivity

__all__ = ["FAULT_CLASSES", "PARAMS", "ABSObserver", "ABSPlant", "ABSResult", "CampaignResult", "FaultClass",
           "ParityR1", "ParityR2", "Scenario", "abs_residuals", "design_tests", "extended_tests",
           "min_magnitudes", "observer_sensitivity", "paper_tests", "residual_generators", "run_campaign",
           "simulate", "test_set"]
