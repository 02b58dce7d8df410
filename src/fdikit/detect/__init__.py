"""Residual processors: threshold rules, GLRT, MHSSPT."""

from .glrt import GLRT, ThresholdDesign, TimeGated, design_threshold, glrt_statistic
from .mhsspt import MHSSPT, MHSSPTCalibration, UniformMeanGaussian, calibrate_densities
from .threshold import Hold, consecutive_count

__all__ = [
    "GLRT",
    "MHSSPT",
    "Hold",
    "MHSSPTCalibration",
    "ThresholdDesign",
    "TimeGated",
    "UniformMeanGaussian",
    "calibrate_densities",
    "consecutive_count",
    "design_threshold",
    "glrt_statistic",
]
