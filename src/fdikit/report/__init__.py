"""Figures and the self-contained HTML report of monitor runs, campaigns and the demo.

* :class:`Report` -- one HTML file that opens offline (plotly.js embedded once), built from
  sections of text, tables and interactive plots; :func:`check_output_path` checks where it goes
  before any work is done;
* :func:`monitor_report`, :func:`campaign_report`, :func:`report_from_files` -- the report of a
  monitor run (metadata, signals with held/invalid samples shaded, residuals with thresholds,
  test statistics, fault probabilities, events timeline, signature matrix) and of a campaign
  (Pd/Pf, D-matrix, confusion matrix, sensitivity/specificity, detection-time histograms, ROC);
* :func:`minmax_decimate` -- display decimation that keeps every bucket's extremes;
* :mod:`fdikit.report.figures` -- matplotlib figures for the terminal (``--plot``): units on
  every axis, events marked, channels split or normalised;
* :func:`progress_steps` -- a rich progress display on standard error for long work.

This package is core: it never imports a system or a command.
"""

from .builders import (
    add_campaign,
    add_events,
    add_monitor,
    add_roc,
    add_signature,
    campaign_report,
    design_hash,
    episode_spans,
    event_records,
    monitor_report,
    monitor_thresholds,
    read_events_jsonl,
    report_from_files,
    roc_curve,
)
from .decimate import minmax_decimate, true_intervals
from .html import Report, check_output_path, encode_array, heatmap_figure, stacked_time_figure
from .progress import progress_steps

__all__ = [
    "Report",
    "add_campaign",
    "add_events",
    "add_monitor",
    "add_roc",
    "add_signature",
    "campaign_report",
    "check_output_path",
    "design_hash",
    "encode_array",
    "episode_spans",
    "event_records",
    "heatmap_figure",
    "minmax_decimate",
    "monitor_report",
    "monitor_thresholds",
    "progress_steps",
    "read_events_jsonl",
    "report_from_files",
    "roc_curve",
    "stacked_time_figure",
    "true_intervals",
]
