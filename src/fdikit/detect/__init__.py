"""Residual processors: threshold rules, GLRT, directional GLRT, MHSSPT (also from labelled real data,
pre-whitened), feature norms, peer checks of redundant sensors (:mod:`.redundancy`),
sensor-fault detectors (stuck, drift, gain, intermittent:
:mod:`.sensor`), banks of tests designed together, and threshold design for a target per
sample, per run or per hour (:mod:`.tail`: block bootstrap and GPD tails), and control limits of
data-driven statistics calibrated on held-out nominal records (:mod:`.calibrated_limits`), and
the EWMA of a statistic with its held-out limit, for slow and small faults (:mod:`.smoothing`)."""

from .bank import TestBank, TestSpec
from .calibrated_limits import (
    CalibratedLimits,
    calibrate_limits,
    fit_calibrated,
    held_out_limit,
    predictive_interval,
)
from .cusum import PeerCUSUM, design_peer_cusum
from .directional import DirectionalGLRT, directional_statistic
from .features import FeatureNorms
from .glrt import GLRT, ThresholdDesign, TimeGated, design_threshold, glrt_statistic
from .mhsspt import (
    MHSSPT,
    LineMeanGaussian,
    MHSSPTCalibration,
    UniformMeanGaussian,
    WarmupMHSSPT,
    WhitenedMHSSPT,
    calibrate_densities,
    calibrate_segments,
    design_calibrated_mhsspt,
    design_mhsspt,
    detection_time,
    extend_ranges,
    final_diagnosis,
    fit_temperature,
    floor_std,
    reliability,
    shrunk_covariance,
)
from .redundancy import PeerCheck, design_peer_check
from .sensor import (
    DriftDetector,
    GainDetector,
    IntermittentDetector,
    StuckDetector,
    design_drift,
    design_gain,
    design_intermittent,
    design_stuck,
)
from .smoothing import EWMA, EWMADesign, choose_lambda, design_ewma, ewma, ewma_tau
from .threshold import ABSOLUTE_DEFAULT, Hold, consecutive_count
from .whiten import VARWhitener

__all__ = [
    "ABSOLUTE_DEFAULT",
    "EWMA",
    "GLRT",
    "MHSSPT",
    "CalibratedLimits",
    "DirectionalGLRT",
    "DriftDetector",
    "EWMADesign",
    "FeatureNorms",
    "GainDetector",
    "Hold",
    "IntermittentDetector",
    "LineMeanGaussian",
    "MHSSPTCalibration",
    "PeerCUSUM",
    "PeerCheck",
    "StuckDetector",
    "TestBank",
    "TestSpec",
    "ThresholdDesign",
    "TimeGated",
    "UniformMeanGaussian",
    "VARWhitener",
    "WarmupMHSSPT",
    "WhitenedMHSSPT",
    "calibrate_densities",
    "calibrate_limits",
    "calibrate_segments",
    "choose_lambda",
    "consecutive_count",
    "design_calibrated_mhsspt",
    "design_drift",
    "design_ewma",
    "design_gain",
    "design_intermittent",
    "design_mhsspt",
    "design_peer_check",
    "design_peer_cusum",
    "design_stuck",
    "design_threshold",
    "detection_time",
    "directional_statistic",
    "ewma",
    "ewma_tau",
    "extend_ranges",
    "final_diagnosis",
    "fit_calibrated",
    "fit_temperature",
    "floor_std",
    "glrt_statistic",
    "held_out_limit",
    "predictive_interval",
    "reliability",
    "shrunk_covariance",
]
