"""One self-contained HTML file: sections of tables, text and interactive plots.

The page embeds plotly.js once (from the ``plotly`` package, so it opens offline, with no
network) and every figure as plain JSON; numeric arrays travel as base64 typed arrays (plotly.js
``{dtype, bdata}``), so a long log costs a few bytes per displayed sample. Long records are
decimated for display by :func:`~fdikit.report.decimate.minmax_decimate` (min/max per bucket, so
no spike disappears).

The page also carries its data for machines: a ``<script type="application/json"
id="fdikit-report-data">`` block with the metadata and every event, and it sets
``document.body.dataset.fdikitRendered`` to the number of plots once all of them are drawn (and
``fdikitErrors`` to any script error), which the browser test reads.
"""

from __future__ import annotations

import base64
import html
import json
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import DataError
from .decimate import minmax_decimate

__all__ = ["Report", "check_output_path", "encode_array", "heatmap_figure", "stacked_time_figure"]

#: Colours of the shaded samples: held by the monitor (all panels), invalid in the source (one panel).
HELD_COLOUR = "rgba(120,120,120,0.25)"
INVALID_COLOUR = "rgba(214,39,40,0.22)"
EVENT_COLOUR = "rgba(214,39,40,0.9)"
#: Announcements drawn as lines across the time panels (all of them are in the events timeline).
MAX_EVENT_MARKS = 40


def check_output_path(path: str | os.PathLike, suffixes: Sequence[str] = (".html", ".htm")) -> Path:
    """Check an output path before any computation: right extension, existing writable folder.

    Raises
    ------
    DataError
        Naming the path and what is wrong with it.
    """
    p = Path(path)
    if suffixes and p.suffix.lower() not in suffixes:
        raise DataError(f"{p}: the output file must end in {' or '.join(suffixes)}")
    parent = p.parent if str(p.parent) else Path(".")
    if not parent.is_dir():
        raise DataError(f"{p}: the folder {str(parent)!r} does not exist")
    if p.is_dir():
        raise DataError(f"{p}: is a folder, not a file")
    if not os.access(parent, os.W_OK) or (p.exists() and not os.access(p, os.W_OK)):
        raise DataError(f"{p}: cannot write there (permission denied)")
    return p


def encode_array(a, dtype: str = "f8") -> dict | list:
    """A numeric array as a plotly.js typed array ``{"dtype", "bdata"[, "shape"]}``.

    NaN stays NaN (a break in a line). ``dtype`` is ``"f8"`` or ``"f4"`` (half the bytes,
    7 significant digits: enough for display).
    """
    arr = np.ascontiguousarray(np.asarray(a, dtype={"f8": "<f8", "f4": "<f4", "i4": "<i4"}[dtype]))
    out: dict[str, Any] = {"dtype": dtype, "bdata": base64.b64encode(arr.tobytes()).decode("ascii")}
    if arr.ndim == 2:
        out["shape"] = f"{arr.shape[0]},{arr.shape[1]}"
    return out


def _label(name: str, unit: str | None) -> str:
    return f"{name} ({unit if unit else '–'})"


def stacked_time_figure(
    t,
    panels: Sequence[Mapping[str, Any]],
    *,
    title: str | None = None,
    held: Sequence[tuple[float, float]] = (),
    events: Sequence[tuple[float, str]] = (),
    max_points: int = 2400,
    panel_height: int = 150,
    t_unit: str = "s",
) -> dict:
    """Stacked panels over one shared time axis (zoom one, all follow).

    Parameters
    ----------
    t : array_like (T,)
        Time, s.
    panels : sequence of dict
        Each ``{"title": str, "unit": str, "traces": [(name, y (T,)), ...]}`` and optionally
        ``"ylabel"``, ``"thresholds": [(label, value), ...]`` (dashed horizontal lines),
        ``"invalid": [(t0, t1), ...]`` (intervals shaded in this panel only), ``"range": (lo, hi)``
        (the initial y range, in data units also on a log axis; a double click autoscales) and
        ``"log": True`` (a logarithmic y axis; values <= 0 are not drawn). A trace name that an
        earlier panel already has shares its legend entry (one click hides it in every panel).
    held : sequence of (t0, t1)
        Intervals shaded in every panel (samples the monitor held).
    events : sequence of (t, label)
        Vertical markers across every panel, labelled at the top (the first
        :data:`MAX_EVENT_MARKS`; the events timeline shows them all).
    max_points : int
        Samples per trace after min/max decimation.

    Returns
    -------
    dict
        A plotly figure (``data``, ``layout``).
    """
    t = np.asarray(t, float)
    n = len(panels)
    if n == 0:
        raise DataError("stacked_time_figure: no panels")
    gap = 0.04 if n > 1 else 0.0
    h = (1.0 - gap * (n - 1)) / n
    data: list[dict] = []
    shapes: list[dict] = []
    annotations: list[dict] = []
    layout: dict[str, Any] = {
        "height": int(panel_height * n + 120),
        "margin": {"l": 80, "r": 30, "t": 50 if title else 30, "b": 50},
        "showlegend": True,
        "legend": {"orientation": "h", "y": -0.08 if n < 4 else -0.03},
        "hovermode": "x",
        "xaxis": {"title": {"text": f"time ({t_unit})"}, "anchor": f"y{n if n > 1 else ''}"},
    }
    if title:
        layout["title"] = {"text": html.escape(title)}
    palette = [
        "#1f77b4",
        "#ff7f0e",
        "#2ca02c",
        "#9467bd",
        "#8c564b",
        "#e377c2",
        "#7f7f7f",
        "#bcbd22",
        "#17becf",
        "#d62728",
    ]
    colours: dict[str, str] = {}  # one colour per trace name across the panels
    shown: set[str] = set()
    for i, p in enumerate(panels):
        k = i + 1
        yname = "y" if k == 1 else f"y{k}"
        ax = "yaxis" if k == 1 else f"yaxis{k}"
        top = 1.0 - i * (h + gap)
        layout[ax] = {
            "domain": [max(top - h, 0.0), top],
            "title": {
                "text": html.escape(_label(p.get("ylabel", p.get("title", "")), p.get("unit"))),
                "font": {"size": 11},
            },
            "zeroline": False,
        }
        if p.get("log"):
            layout[ax]["type"] = "log"
            if p.get("range") is not None:  # plotly takes a log axis's range as log10 values
                layout[ax]["range"] = [float(np.log10(v)) for v in p["range"]]
        elif p.get("range") is not None:
            layout[ax]["range"] = list(p["range"])
        for name, y in p["traces"]:
            y = np.asarray(y, float)
            td, yd = minmax_decimate(t, y, max_points)
            trace = {
                "type": "scatter",
                "mode": "lines",
                "name": str(name),
                "x": encode_array(td),
                "y": encode_array(yd, "f4"),
                "yaxis": yname,
                "line": {"width": 1, "color": colours.setdefault(str(name), palette[len(colours) % 10])},
                "legendgroup": str(name),
            }
            if str(name) in shown:
                trace["showlegend"] = False  # the same series in another panel: one legend entry
            shown.add(str(name))
            data.append(trace)
        for label, value in p.get("thresholds", ()):
            if p.get("log") and not value > 0:
                continue  # not on a logarithmic axis
            shapes.append(
                {
                    "type": "line",
                    "xref": "x domain",
                    "x0": 0,
                    "x1": 1,
                    "yref": yname,
                    "y0": value,
                    "y1": value,
                    "line": {"dash": "dash", "width": 1.2, "color": "black"},
                }
            )
            annotations.append(
                {
                    "xref": "x domain",
                    "x": 1.0,
                    "xanchor": "right",
                    "yref": yname,
                    # shapes take data values on a log axis, annotations the log10 of them
                    "y": float(np.log10(value)) if p.get("log") else value,
                    "yanchor": "bottom",
                    "text": html.escape(str(label)),
                    "showarrow": False,
                    "font": {"size": 9},
                }
            )
        for a, b in p.get("invalid", ()):
            shapes.append(
                {
                    "type": "rect",
                    "xref": "x",
                    "x0": a,
                    "x1": b,
                    "yref": f"{yname} domain",
                    "y0": 0,
                    "y1": 1,
                    "fillcolor": INVALID_COLOUR,
                    "line": {"width": 0},
                    "layer": "below",
                }
            )
        annotations.append(
            {
                "xref": "x domain",
                "x": 0.0,
                "xanchor": "left",
                "yref": f"{yname} domain",
                "y": 1.0,
                "yanchor": "bottom",
                "text": f"<b>{html.escape(str(p.get('title', '')))}</b>",
                "showarrow": False,
                "font": {"size": 11},
            }
        )
        if k > 1:
            layout[ax]["anchor"] = "x"
    for a, b in held:
        shapes.append(
            {
                "type": "rect",
                "xref": "x",
                "x0": a,
                "x1": b,
                "yref": "paper",
                "y0": 0,
                "y1": 1,
                "fillcolor": HELD_COLOUR,
                "line": {"width": 0},
                "layer": "below",
            }
        )
    for te, label in events[:MAX_EVENT_MARKS]:
        shapes.append(
            {
                "type": "line",
                "xref": "x",
                "x0": te,
                "x1": te,
                "yref": "paper",
                "y0": 0,
                "y1": 1,
                "line": {"width": 1, "color": EVENT_COLOUR, "dash": "dot"},
            }
        )
        annotations.append(
            {
                "xref": "x",
                "x": te,
                "yref": "paper",
                "y": 1.0,
                "yanchor": "bottom",
                "text": html.escape(str(label)),
                "showarrow": False,
                "textangle": -30,
                "font": {"size": 9, "color": EVENT_COLOUR},
            }
        )
    layout["shapes"] = shapes
    layout["annotations"] = annotations
    return {"data": data, "layout": layout}


def heatmap_figure(
    z,
    x_labels: Sequence[str],
    y_labels: Sequence[str],
    *,
    title: str = "",
    colorbar: str = "",
    text=None,
    zmin: float | None = None,
    zmax: float | None = None,
    x_title: str = "",
    y_title: str = "",
    colorscale: str = "Blues",
) -> dict:
    """A labelled heat map (signature matrix, D-matrix, Pd/Pf table, confusion matrix).

    ``z`` has shape (len(y_labels), len(x_labels)); ``text`` (same shape, strings) is written in
    the cells (default: ``z`` to 3 significant digits).
    """
    z = np.asarray(z, float)
    if z.shape != (len(y_labels), len(x_labels)):
        raise DataError(
            f"heatmap_figure: z has shape {z.shape}, labels give {(len(y_labels), len(x_labels))}"
        )
    if text is None:
        text = [["" if not np.isfinite(v) else f"{v:.3g}" for v in row] for row in z]
    zl = [[None if not np.isfinite(v) else float(v) for v in row] for row in z]
    trace = {
        "type": "heatmap",
        "z": zl,
        "x": [str(s) for s in x_labels],
        "y": [str(s) for s in y_labels],
        "text": text,
        "texttemplate": "%{text}",
        "colorscale": colorscale,
        "colorbar": {"title": {"text": html.escape(colorbar)}},
        "hoverongaps": False,
    }
    if zmin is not None:
        trace["zmin"] = zmin
    if zmax is not None:
        trace["zmax"] = zmax
    layout = {
        "title": {"text": html.escape(title)},
        "height": int(140 + 28 * len(y_labels)),
        "margin": {"l": 110, "r": 30, "t": 50, "b": 80},
        # automargin: long row labels push the plot right instead of running under the axis title
        "xaxis": {
            "title": {"text": html.escape(x_title)},
            "side": "bottom",
            "type": "category",
            "automargin": True,
        },
        "yaxis": {
            "title": {"text": html.escape(y_title)},
            "autorange": "reversed",
            "type": "category",
            "automargin": True,
        },
    }
    return {"data": [trace], "layout": layout}


def _json_script(obj: Any) -> str:
    # inside <script>, "</" would end the element: escape it (valid JSON either way)
    return json.dumps(obj, allow_nan=False, default=_json_default).replace("</", "<\\/")


def _json_default(o: Any) -> Any:
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.bool_):
        return bool(o)
    if isinstance(o, np.integer):
        return int(o)
    if isinstance(o, np.floating):
        return float(o)
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON-able: {type(o).__name__}")


def _clean(obj: Any) -> Any:
    """NaN and inf become None (JSON null) throughout."""
    if isinstance(obj, dict):
        return {str(k): _clean(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_clean(v) for v in obj]
    if isinstance(obj, float | np.floating):
        return float(obj) if np.isfinite(obj) else None
    if isinstance(obj, np.ndarray):
        return _clean(obj.tolist())
    return obj


def _fmt(v: Any) -> str:
    if isinstance(v, bool | np.bool_):
        return "yes" if v else "no"
    if isinstance(v, float | np.floating):
        return "–" if not np.isfinite(v) else f"{v:.5g}"
    if v is None:
        return "–"
    if isinstance(v, dict):
        return ", ".join(f"{k}={_fmt(x)}" for k, x in v.items())
    if isinstance(v, list | tuple):
        return ", ".join(_fmt(x) for x in v)
    return str(v)


class Report:
    """An HTML report under construction: sections of text, tables and plotly figures.

    Parameters
    ----------
    title : str
        Page title.
    max_points : int
        Samples per displayed trace (min/max decimation beyond it).

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> rep = Report("example")
    >>> rep.section("signals")
    >>> t = np.arange(1000) * 0.01
    >>> _ = rep.figure(stacked_time_figure(t, [{"title": "y", "unit": "m", "traces": [("y", np.sin(t))]}]))
    >>> p = rep.write(os.path.join(tempfile.mkdtemp(), "r.html"))
    >>> p.stat().st_size > 1_000_000   # plotly.js is embedded
    True
    """

    def __init__(self, title: str, *, max_points: int = 2400):
        self.title = str(title)
        self.max_points = int(max_points)
        self.data: dict[str, Any] = {"title": self.title}
        self._sections: list[tuple[str, str, list[str]]] = []
        self._figures: list[dict] = []

    # ------------------------------------------------------------------ building
    def section(self, title: str, intro: str | None = None) -> None:
        """Start a new section (everything added next goes into it)."""
        sid = f"s{len(self._sections) + 1}"
        self._sections.append((sid, str(title), []))
        if intro:
            self.text(intro)

    def _blocks(self) -> list[str]:
        if not self._sections:
            self.section(self.title)
        return self._sections[-1][2]

    def text(self, text: str) -> None:
        """A paragraph (plain text, escaped)."""
        self._blocks().append(f"<p>{html.escape(str(text))}</p>")

    def pre(self, text: str, *, summary: str | None = None) -> None:
        """Preformatted text (a config file, a tree listing); folded under ``summary`` if given."""
        body = f"<pre>{html.escape(str(text))}</pre>"
        if summary:
            body = f"<details><summary>{html.escape(summary)}</summary>{body}</details>"
        self._blocks().append(body)

    def table(
        self,
        rows: Sequence[Mapping[str, Any]] | Mapping[str, Any],
        *,
        columns: Sequence[str] | None = None,
        caption: str | None = None,
        max_rows: int = 1000,
        css_class: str = "",
    ) -> None:
        """A table: a mapping is shown as key/value rows, a list of mappings as one row each."""
        if isinstance(rows, Mapping):
            rows = [{"key": k, "value": v} for k, v in rows.items()]
            columns = ["key", "value"]
        rows = list(rows)
        if columns is None:
            columns = list(dict.fromkeys(k for r in rows for k in r))
        head = "".join(f"<th>{html.escape(str(c))}</th>" for c in columns)
        body = []
        for r in rows[:max_rows]:
            body.append(
                "<tr>" + "".join(f"<td>{html.escape(_fmt(r.get(c)))}</td>" for c in columns) + "</tr>"
            )
        more = ""
        if len(rows) > max_rows:
            more = (
                f"<p class='note'>{len(rows) - max_rows} more rows not shown (all are in the page data).</p>"
            )
        cap = f"<caption>{html.escape(caption)}</caption>" if caption else ""
        cls = f" class='{css_class}'" if css_class else ""
        self._blocks().append(
            f"<table{cls}>{cap}<thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>{more}"
        )

    def figure(self, fig: Mapping[str, Any], *, caption: str | None = None) -> str:
        """Add a plotly figure (``{"data", "layout"}``); returns its element id."""
        fid = f"plot{len(self._figures) + 1}"
        layout = dict(fig.get("layout", {}))
        layout.setdefault("template", None)
        self._figures.append({"id": fid, "data": list(fig["data"]), "layout": layout})
        h = int(layout.get("height", 420))
        cap = f"<p class='caption'>{html.escape(caption)}</p>" if caption else ""
        self._blocks().append(f"<div class='plot' id='{fid}' style='height:{h}px'></div>{cap}")
        return fid

    @property
    def n_figures(self) -> int:
        return len(self._figures)

    # ------------------------------------------------------------------ output
    def to_html(self) -> str:
        from plotly.offline import get_plotlyjs

        nav = "".join(
            f"<li><a href='#{sid}'>{html.escape(title)}</a></li>" for sid, title, _ in self._sections
        )
        body = "".join(
            f"<section id='{sid}'><h2>{html.escape(title)}</h2>{''.join(blocks)}</section>"
            for sid, title, blocks in self._sections
        )
        data = _json_script(_clean(self.data))
        figs = _json_script(_clean(self._figures))
        return (
            "<!DOCTYPE html>\n<html lang='en'><head><meta charset='utf-8'>"
            f"<title>{html.escape(self.title)}</title>"
            "<meta name='viewport' content='width=device-width, initial-scale=1'>"
            f"<style>{_CSS}</style>"
            f"<script>{_ERRORS_JS}</script>"
            f"<script type='text/javascript'>{get_plotlyjs()}</script>"
            "</head><body>"
            f"<header><h1>{html.escape(self.title)}</h1><nav><ul>{nav}</ul></nav></header>"
            f"<main>{body}</main>"
            f"<script type='application/json' id='fdikit-report-data'>{data}</script>"
            f"<script type='application/json' id='fdikit-figures'>{figs}</script>"
            f"<script>{_RENDER_JS}</script>"
            "</body></html>\n"
        )

    def write(self, path: str | os.PathLike) -> Path:
        """Write the page to ``path`` atomically (:func:`fdikit.base.outputs.open_output`: a full disk
        is a DataError naming the file, never half a page); returns the path."""
        from ..base.outputs import open_output

        p = check_output_path(path)
        text = self.to_html()
        with open_output(p, "w", encoding="utf-8") as fh:
            fh.write(text)
        return p


_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;margin:0;color:#222;background:#fafafa}
header{background:#1f3b57;color:#fff;padding:10px 24px}header h1{margin:4px 0;font-size:22px}
nav ul{list-style:none;padding:0;margin:4px 0;display:flex;flex-wrap:wrap;gap:14px}
nav a{color:#cfe3f7;text-decoration:none;font-size:14px}main{padding:8px 24px}
section{background:#fff;border:1px solid #ddd;border-radius:6px;padding:8px 16px;margin:14px 0}
h2{font-size:18px;margin:8px 0}table{border-collapse:collapse;margin:8px 0;font-size:13px}
td,th{border:1px solid #ccc;padding:3px 8px;text-align:left;vertical-align:top}th{background:#eef2f6}
caption{text-align:left;font-weight:bold;padding:4px 0}pre{background:#f4f4f4;padding:8px;overflow:auto;
font-size:12px;max-height:420px}.plot{width:100%}.caption,.note{font-size:12px;color:#555}
"""

# Collects script errors (also console.error calls) so that a headless check can read them.
_ERRORS_JS = """
window.__fdikitErrors=[];
window.addEventListener('error',function(e){window.__fdikitErrors.push(String(e.message||e));});
window.addEventListener('unhandledrejection',function(e){window.__fdikitErrors.push(String(e.reason));});
"""

# Draws the figures one after the other, yielding to the browser between them, so that the top
# of the page shows at once while the rest is drawn.
_RENDER_JS = """
(function(){
  var figs = JSON.parse(document.getElementById('fdikit-figures').textContent);
  var cfg = {responsive: true, displaylogo: false, scrollZoom: true};
  var i = 0;
  function done(){
    document.body.dataset.fdikitRendered = String(figs.length);
    document.body.dataset.fdikitErrors = String(window.__fdikitErrors.length);
  }
  function next(){
    if (i >= figs.length) { done(); return; }
    var f = figs[i++];
    Plotly.newPlot(f.id, f.data, f.layout, cfg).then(function(){ setTimeout(next, 0); }).catch(function(e){
      window.__fdikitErrors.push(String(e));
      document.body.dataset.fdikitErrors = String(window.__fdikitErrors.length);
    });
  }
  next();
})();
"""
