"""Runnable demonstrations composed across the papers' systems: the tour of ``fdikit demo`` (its
sections, :mod:`.sections`, and its HTML report, :mod:`.report`) and the simulated example logs of
``fdikit example-log`` (:mod:`.example_logs`).

This layer sits above :mod:`fdikit.systems` (it may import every system; no system imports it) and
below :mod:`fdikit.commands`, which only parse arguments, call these functions and print.
"""

from .example_logs import SYSTEMS, write_example_logs
from .report import default_report_path, write_report
from .sections import run_section, run_sections, section_linear, sections

__all__ = ["SYSTEMS", "default_report_path", "run_section", "run_sections", "section_linear", "sections",
           "write_example_logs", "write_report"]
