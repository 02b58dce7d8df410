"""Evaluation: detectability bounds (the Neyman-Pearson bound of a known fault signature) and the
progress display of long campaigns. The papers' campaigns are in :mod:`fdikit.systems`
(e.g. :func:`fdikit.systems.abs.run_campaign`)."""

from .detectability import known_signal_dprime
from .progress import progress_bar

__all__ = ["known_signal_dprime", "progress_bar"]
