"""Monte Carlo evaluation campaigns and FDI metrics (Pd, Pf, sensitivity, specificity), and the
complete ABS diagnoser (:mod:`fdikit.evaluate.abs_diagnoser`)."""

from .abs_diagnoser import ABSDiagnoser, abs_tree, complete_campaign
from .campaign import (
    PAPER_TABLE_III,
    PAPER_TABLE_IV,
    PAPER_TABLE_V,
    CampaignResult,
    TestBank,
    TestSpec,
    abs_residuals,
    design_tests,
    diagnose_ml,
    diagnose_tree,
    extended_tests,
    gp1_grid,
    min_magnitudes,
    paper_tests,
    residual_generators,
    run_campaign,
    test_set,
)

__all__ = [
    "PAPER_TABLE_III",
    "PAPER_TABLE_IV",
    "PAPER_TABLE_V",
    "ABSDiagnoser",
    "CampaignResult",
    "TestBank",
    "TestSpec",
    "abs_residuals",
    "abs_tree",
    "complete_campaign",
    "design_tests",
    "diagnose_ml",
    "diagnose_tree",
    "extended_tests",
    "gp1_grid",
    "min_magnitudes",
    "paper_tests",
    "residual_generators",
    "run_campaign",
    "test_set",
]
