"""Evaluation: detectability bounds (the Neyman-Pearson bound of a known fault signature), the
progress display of long campaigns, and distributed execution (:class:`Engine`: local processes
or Dask; :func:`run_chunked`: a campaign's runs in chunks as tasks, with per-run seeds the same
numbers for any number of workers), and :func:`validate`: a saved design's false-alarm
claims re-measured on new nominal logs (``fdikit validate``). The papers' campaigns are in
:mod:`fdikit.systems` (e.g. :func:`fdikit.systems.abs.run_campaign`)."""

from .detectability import known_signal_dprime
from .distributed import Engine, chunk_bounds, run_chunked
from .progress import progress_bar
from .validate import announcement_claim, claims_table, validate

__all__ = ["Engine", "announcement_claim", "chunk_bounds", "claims_table", "known_signal_dprime",
           "progress_bar", "run_chunked", "validate"]
