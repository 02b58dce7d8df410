"""Residual processors: threshold rules, GLRT, directional GLRT, MHSSPT, feature norms, and banks
of tests designed together."""

from .bank import TestBank, TestSpec
from .directional import DirectionalGLRT, directional_statistic
from .features import FeatureNorms
from .glrt import GLRT, ThresholdDesign, TimeGated, design_threshold, glrt_statistic
from .mhsspt import (
    MHSSPT,
    MHSSPTCalibration,
    UniformMeanGaussian,
    WarmupMHSSPT,
    calibrate_densities,
    extend_ranges,
    floor_std,
)
from .threshold import Hold, consecutive_count

__all__ = [
    "GLRT",
    "MHSSPT",
    "DirectionalGLRT",
    "FeatureNorms",
    "Hold",
    "MHSSPTCalibration",
    "TestBank",
    "TestSpec",
    "ThresholdDesign",
    "TimeGated",
    "UniformMeanGaussian",
    "WarmupMHSSPT",
    "calibrate_densities",
    "consecutive_count",
    "design_threshold",
    "directional_statistic",
    "extend_ranges",
    "floor_std",
    "glrt_statistic",
]
