"""Residual processors: threshold rules, GLRT, CUSUM, MHSSPT."""

from .threshold import Hold, consecutive_count

__all__ = ["Hold", "consecutive_count"]
