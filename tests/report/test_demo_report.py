"""The report ``fdikit demo`` ends with (issue 18): every section of the demo has at least one plot,
and every time plot has units on its axes. The page's structure is read (sections, plot divs and
the figures' JSON), not pixels; ``tests/report/test_browser.py`` renders the whole demo report.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

_SECTION = re.compile(r"<section id='s\d+'><h2>(.*?)</h2>(.*?)</section>", re.S)
_UNIT = re.compile(r"\(([^()]+)\)\s*$")


def _page(path: Path) -> tuple[list[tuple[str, int]], dict, list[dict]]:
    text = path.read_text(encoding="utf-8")
    sections = [(title, body.count("class='plot'")) for title, body in _SECTION.findall(text)]
    data = json.loads(re.search(r"id='fdikit-report-data'>(.*?)</script>", text, re.S).group(1))
    figs = json.loads(re.search(r"id='fdikit-figures'>(.*?)</script>", text, re.S).group(1))
    return sections, data, figs


def sections_without_plots(sections: list[tuple[str, int]], names) -> list[str]:
    """Demo sections with no plot in their own section or in a ``"<name>: ..."`` section."""
    bad = []
    for name in names:
        n = sum(k for title, k in sections if title.lower() == name or title.lower().startswith(f"{name}:"))
        if n == 0:
            bad.append(name)
    return bad


def _time_axes_without_units(figs: list[dict]) -> list[str]:
    """Axes of the time plots (x axis "time (s)") whose title has no "(unit)"."""
    bad = []
    for f in figs:
        lay = f["layout"]
        if lay.get("xaxis", {}).get("title", {}).get("text") != "time (s)":
            continue
        for k, ax in lay.items():
            if re.fullmatch(r"yaxis\d*", k) and not _UNIT.search(ax.get("title", {}).get("text", "")):
                bad.append(f"{f['id']} {k}: {ax.get('title')}")
    return bad


def _run_demo(tmp_path, capsys, only=None) -> tuple[dict, Path]:
    from fdikit.cli import main

    out = tmp_path / "demo.html"
    args = ["demo", "--json", "--report", str(out)] + (["--only", *only] if only else [])
    assert main(args) == 0
    lines = [ln for ln in capsys.readouterr().out.splitlines() if ln.strip()]
    assert len(lines) == 1, lines[:3]  # --json prints exactly one JSON object
    summary = json.loads(lines[0])
    assert summary["report"] == str(out) and out.exists()
    return summary, out


def test_the_section_check_can_fail():
    sections = [("Demo", 0), ("linear", 0), ("linear: Events", 1), ("abs", 0), ("car", 1)]
    assert sections_without_plots(sections, ["linear", "abs", "car"]) == ["abs"]
    figs = [
        {
            "id": "plot1",
            "layout": {
                "xaxis": {"title": {"text": "time (s)"}},
                "yaxis": {"title": {"text": "speed (m/s)"}},
                "yaxis2": {"title": {"text": "speed"}},
            },
        }
    ]
    assert _time_axes_without_units(figs) == ["plot1 yaxis2: {'text': 'speed'}"]


def test_demo_report_quick_sections_each_have_a_plot(tmp_path, capsys):
    """The quick sections (~10 s): linear, the aircraft reconstruction, the ABS stop, the car."""
    only = ["linear", "reconstruct", "abs", "car"]
    _, path = _run_demo(tmp_path, capsys, only)
    sections, data, figs = _page(path)
    assert sections_without_plots(sections, only) == []
    assert all(data["figures_per_section"][n] >= 1 for n in only), data["figures_per_section"]
    assert _time_axes_without_units(figs) == []
    titles = [f["layout"].get("title", {}).get("text", "") for f in figs]
    assert "aircraft rudder fault reconstruction" in titles and "ABS stop (nominal, 23 dB)" in titles
    # the reconstruction plot carries f and both reconstructions, in rad
    rec = figs[titles.index("aircraft rudder fault reconstruction")]
    assert {d["name"] for d in rec["data"]} >= {"f (injected)", "f̂ on A + ΔA", "f̂ on the nominal A"}
    assert rec["layout"]["yaxis"]["title"]["text"].endswith("(rad)")
    # the ABS stop: the slip panel with the desired slip drawn
    stop = figs[titles.index("ABS stop (nominal, 23 dB)")]
    assert any(a.get("text") == "desired slip 0.2" for a in stop["layout"]["annotations"])


@pytest.mark.slow
def test_demo_report_every_section_has_a_plot(tmp_path, capsys):
    """The whole demo (~30-60 s): each of its sections, also abs_diagnosis, abs_directional and
    car_monitor, has a plot; the car monitor's announcement is in the page."""
    from fdikit.commands.demo import sections as demo_sections

    summary, path = _run_demo(tmp_path, capsys)
    names = list(demo_sections())
    assert set(names) <= set(summary)
    sections, data, figs = _page(path)
    assert sections_without_plots(sections, names) == []
    assert all(data["figures_per_section"][n] >= 1 for n in names), data["figures_per_section"]
    assert _time_axes_without_units(figs) == []
    titles = [f["layout"].get("title", {}).get("text", "") for f in figs]
    for t in (
        "GLRT statistics of the diagnosed records",
        "I_w -2 %: directional test and estimate",
        "fault probabilities",
    ):
        assert t in titles, titles
    assert any(e["hypothesis"] == "brake_actuator" for e in data.get("events", []))
