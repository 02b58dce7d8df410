"""Matplotlib figures for the terminal (``--plot FILE``): units on every axis, events marked,
channels split into panels or normalised so that none swamps another.

* :func:`panel_figure` -- a grid of time panels sharing the time axis (each panel its own
  y-scale and unit), with vertical event markers, thresholds and shaded stretches;
* :func:`normalise` -- a channel divided by its fault-free spread, for panels that overlay
  channels of different sizes;
* :func:`axes_without_units` -- the axes of a figure whose labels lack a unit (the figure tests
  call it on every ``--plot`` figure).
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ..errors import DataError

__all__ = [
    "EVENT_COLOUR",
    "axes_without_units",
    "mark_events",
    "monitor_figure",
    "normalise",
    "panel_figure",
    "save",
]

EVENT_COLOUR = "tab:red"
_UNIT = re.compile(r"\(([^()]+)\)\s*$")


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def normalise(y, ref_mask=None, *, q: float = 99.0) -> tuple[np.ndarray, float]:
    """``y`` divided by its ``q``-th percentile of ``|y|`` over ``ref_mask`` (e.g. before the fault).

    Returns the normalised values and the scale (1 when the reference is empty or all zero), so a
    plot can say what 1 means: "the largest fault-free value".
    """
    y = np.asarray(y, float)
    ref = y if ref_mask is None else y[np.asarray(ref_mask, bool)]
    ref = np.abs(ref[np.isfinite(ref)])
    s = float(np.percentile(ref, q)) if ref.size else 0.0
    if not np.isfinite(s) or s <= 0:
        s = 1.0
    return y / s, s


def mark_events(
    ax, events: Sequence[tuple[float, str]], *, label: bool = True, colour: str = EVENT_COLOUR
) -> None:
    """Vertical dotted lines at the events' times, labelled at the top of ``ax``."""
    for i, (t, text) in enumerate(events[:30]):
        ax.axvline(t, color=colour, ls=":", lw=1.0)
        if label:
            ax.annotate(
                str(text),
                (t, 1.0),
                xycoords=("data", "axes fraction"),
                xytext=(2, -2 - 9 * (i % 3)),
                textcoords="offset points",
                fontsize=6,
                color=colour,
                va="top",
            )


def panel_figure(
    t,
    panels: Sequence[Any],
    *,
    title: str | None = None,
    events: Sequence[tuple[float, str]] = (),
    shade: Sequence[tuple[float, float, str]] = (),
    t_label: str = "time (s)",
    panel_size=(6.5, 1.9),
    max_points: int = 6000,
):
    """A figure of time panels that share the time axis.

    Parameters
    ----------
    t : array_like (T,)
        Time, s.
    panels : sequence of dict, or sequence of sequences of dict
        One column of panels, or several columns (each its own list). A panel is ``{"title",
        "ylabel", "unit", "traces": [(label, y (T,)) or (label, y, style dict)], "thresholds":
        [(label, value)], "ylim": (lo, hi), "legend": bool, "log": bool}``; its y-label is
        ``"ylabel (unit)"``.
    events : sequence of (t, label)
        Marked in every panel (labelled in the top row).
    shade : sequence of (t0, t1, label[, colour])
        Stretches shaded in every panel (e.g. a fault window, held samples; grey by default).
    max_points : int
        Longer records are drawn min/max-decimated (no spike disappears).

    Returns
    -------
    matplotlib.figure.Figure
    """
    from .decimate import minmax_decimate

    plt = _plt()
    if not panels:
        raise DataError("panel_figure: no panels")
    columns = [list(c) for c in panels] if not isinstance(panels[0], Mapping) else [list(panels)]
    nrows = max(len(c) for c in columns)
    ncols = len(columns)
    fig = plt.figure(figsize=(panel_size[0] * ncols, panel_size[1] * nrows + 0.9), layout="constrained")
    outer = fig.add_gridspec(1, ncols)
    t = np.asarray(t, float)
    first = None
    for c, col in enumerate(columns):
        inner = outer[0, c].subgridspec(len(col), 1)
        col_axes = []
        for r, p in enumerate(col):
            ax = fig.add_subplot(inner[r, 0], sharex=first)
            first = first or ax
            col_axes.append(ax)
            for tr in p["traces"]:
                label, y = tr[0], tr[1]
                style = dict(tr[2]) if len(tr) > 2 else {}
                style.setdefault("lw", 0.9)
                td, yd = minmax_decimate(t, np.asarray(y, float), max_points)
                ax.plot(td, yd, label=str(label), **style)
            for label, v in p.get("thresholds", ()):
                ax.axhline(v, color="k", ls="--", lw=0.8)
                ax.annotate(
                    str(label),
                    (1.0, v),
                    xycoords=("axes fraction", "data"),
                    xytext=(-2, 2),
                    textcoords="offset points",
                    fontsize=6,
                    ha="right",
                )
            for sh in shade:
                ax.axvspan(sh[0], sh[1], color=sh[3] if len(sh) > 3 else "0.6", alpha=0.15, lw=0)
            mark_events(ax, events, label=(r == 0))
            ax.set_ylabel(f"{p.get('ylabel', p.get('title', ''))} ({p.get('unit') or '–'})", fontsize=7)
            if p.get("title"):
                ax.set_title(str(p["title"]), fontsize=8)
            if p.get("log"):
                ax.set_yscale("symlog", linthresh=1.0)
            if p.get("ylim") is not None:
                ax.set_ylim(*p["ylim"])
            if p.get("legend", len(p["traces"]) > 1):
                ax.legend(fontsize=6, loc="upper left")
            ax.grid(True, alpha=0.3)
            ax.tick_params(labelsize=7)
            if r < len(col) - 1:
                ax.tick_params(labelbottom=False)
        col_axes[-1].set_xlabel(t_label, fontsize=8)
    if title:
        fig.suptitle(title, fontsize=10)
    return fig


def save(fig, path: str, dpi: int = 110) -> str:
    """Save and close ``fig``; returns ``path``."""
    plt = _plt()
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return str(path)


def _has_content(ax) -> bool:
    return bool(ax.lines or ax.collections or ax.images or ax.patches or ax.containers)


def axes_without_units(fig) -> list[str]:
    """Axes of ``fig`` whose x or y label lacks a unit in brackets, e.g. ``"time (s)"``.

    An axis counts as labelled when its own label ends in ``(unit)``, or when it shares that axis
    with a labelled neighbour (stacked panels label the shared time axis once, at the bottom), or
    the figure has such a ``supxlabel``/``supylabel``. Colour bars need a unit on their long
    axis. Hidden and empty axes are skipped. Returns a description of each offender (empty list:
    every axis has its unit).
    """
    bad = []
    sup = {k: getattr(fig, f"_sup{k}label", None) for k in ("x", "y")}
    sup_ok = {k: s is not None and bool(_UNIT.search(s.get_text())) for k, s in sup.items()}
    for i, ax in enumerate(fig.axes):
        if not ax.get_visible():
            continue
        cb = getattr(ax, "_colorbar", None)
        if cb is not None:
            lab = ax.get_ylabel() if cb.orientation == "vertical" else ax.get_xlabel()
            if not _UNIT.search(lab):
                bad.append(f"colour bar {i}: label {lab!r} has no unit")
            continue
        if not _has_content(ax):
            continue
        for k in ("x", "y"):
            lab = ax.get_xlabel() if k == "x" else ax.get_ylabel()
            if _UNIT.search(lab) or sup_ok[k]:
                continue
            shared = (ax.get_shared_x_axes() if k == "x" else ax.get_shared_y_axes()).get_siblings(ax)
            if any(
                _UNIT.search(s.get_xlabel() if k == "x" else s.get_ylabel()) for s in shared if s is not ax
            ):
                continue
            bad.append(f"axes {i} ({ax.get_title()!r}): {k}-label {lab!r} has no unit")
    return bad


def monitor_figure(
    signals,
    result,
    path: str | None = None,
    *,
    thresholds=None,
    level: float | None = None,
    run: int = 0,
    max_panels: int = 8,
):
    """The terminal figure of a monitor run (``fdikit monitor --plot``): input signals (left),
    residuals with their thresholds (middle), statistics and probabilities (right), one panel per
    channel (at most ``max_panels`` per column), announcements marked, held samples shaded.

    ``thresholds`` is ``{channel: value or (value, absolute)}`` (e.g.
    :func:`fdikit.report.monitor_thresholds`). Returns the saved path, or the figure when
    ``path`` is None.
    """
    from .decimate import true_intervals

    thr = {}
    for k, v in (thresholds or {}).items():
        thr[k] = (float(v[0]), bool(v[1])) if isinstance(v, tuple | list) else (float(v), False)

    def col(sig, skip=()):
        out = []
        if sig is None:
            return out
        for j, (n, u) in enumerate(zip(sig.names, sig.units)):
            if n in skip or len(out) >= max_panels:
                continue
            p = {"title": n, "ylabel": n, "unit": u, "traces": [(n, sig.values[run, :, j])], "legend": False}
            if n in thr:
                v, absolute = thr[n]
                p["thresholds"] = [("threshold", v)] + ([("-threshold", -v)] if absolute else [])
            out.append(p)
        return out

    st = result.statistics
    probs = [n for n in st.names if n.startswith("P:") and not n.endswith(":alarm")]
    alarms = [n for n in st.names if n.endswith(":alarm") or n.startswith("A:")]
    right = col(st, skip=set(probs) | set(alarms))
    if probs:
        right.append(
            {
                "title": "fault probabilities",
                "ylabel": "probability",
                "unit": "–",
                "ylim": (-0.05, 1.05),
                "thresholds": [("announce", level)] if level is not None else [],
                "traces": [(n, st[n][run]) for n in probs[:12]],
            }
        )
    columns = [c for c in (col(signals), col(result.residuals), right) if c]
    valid = result.valid[run] if result.valid is not None else np.ones(signals.n_samples, bool)
    shade = [(a, b, "held", "0.5") for a, b in true_intervals(signals.t, ~valid)]
    events = [(e.t, e.hypothesis) for e in result.events if e.run == run]
    fig = panel_figure(
        signals.t,
        columns,
        title="monitor run (grey: held samples)",
        events=events,
        shade=shade,
        panel_size=(5.0, 1.5),
    )
    return fig if path is None else save(fig, path)
