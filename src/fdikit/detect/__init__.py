"""Residual processors: threshold rules, GLRT, CUSUM, MHSSPT."""

from .glrt import GLRT, ThresholdDesign, TimeGated, design_threshold, glrt_statistic
from .threshold import Hold, consecutive_count

__all__ = ["GLRT", "Hold", "ThresholdDesign", "TimeGated", "consecutive_count", "design_threshold",
           "glrt_statistic"]
