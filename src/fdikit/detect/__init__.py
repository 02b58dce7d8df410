"""Residual processors: threshold rules, GLRT, MHSSPT."""

from .glrt import GLRT, ThresholdDesign, TimeGated, design_threshold, glrt_statistic
from .mhsspt import MHSSPT, UniformMeanGaussian
from .threshold import Hold, consecutive_count

__all__ = ["GLRT", "MHSSPT", "Hold", "ThresholdDesign", "TimeGated", "UniformMeanGaussian",
           "consecutive_count", "design_threshold", "glrt_statistic"]
