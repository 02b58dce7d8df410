"""Evaluation: detectability bounds (the Neyman-Pearson bound of a known fault signature), the
progress display of long campaigns, and distributed execution (:class:`Engine`: local processes
or Dask; :func:`run_chunked`: a campaign's runs in chunks as tasks, with per-run seeds the same
numbers for any number of workers). The papers' campaigns are in :mod:`fdikit.systems`
(e.g. :func:`fdikit.systems.abs.run_campaign`)."""

from .detectability import known_signal_dprime
from .distributed import Engine, chunk_bounds, run_chunked
from .progress import progress_bar

__all__ = ["Engine", "chunk_bounds", "known_signal_dprime", "progress_bar", "run_chunked"]
