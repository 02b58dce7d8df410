"""Every kind of HTML report opened in a real browser (headless Chromium, DevTools protocol).

For each report: the page loads from a file with the network switched off (DevTools
``Network.emulateNetworkConditions`` offline, plus a proxy and host rules that lead nowhere), no
console error, no uncaught exception, no request for anything but the file itself (so plotly.js
really is embedded), and every plot div holds a rendered plotly SVG with its axes. Skips with a
reason where Chromium or the websocket client is absent (``.ci/run`` installs Debian's chromium).
"""

from __future__ import annotations

import json
import shutil
import subprocess
import tempfile
import time
import urllib.request
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
RAV4 = ROOT.parent / "shared" / "data" / "rav4-highway"
CHROMIUM = next(
    (shutil.which(n) for n in ("chromium", "chromium-browser", "google-chrome") if shutil.which(n)), None
)


class Browser:
    """A headless Chromium driven over the DevTools protocol (websocket-client)."""

    def __init__(self, exe: str):
        import websocket

        self._ws_mod = websocket
        self.profile = tempfile.mkdtemp(prefix="fdikit-chromium-")
        self.proc = subprocess.Popen(
            [
                exe,
                "--headless=new",
                "--no-sandbox",
                "--disable-gpu",
                "--no-first-run",
                "--no-default-browser-check",
                "--disable-extensions",
                "--disable-background-networking",
                "--disable-component-update",
                "--proxy-server=127.0.0.1:9",
                "--host-resolver-rules=MAP * ~NOTFOUND, EXCLUDE 127.0.0.1",
                "--remote-debugging-port=0",
                "--remote-allow-origins=*",
                f"--user-data-dir={self.profile}",
                "--window-size=1280,900",
                "about:blank",
            ],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )
        port = None
        t0 = time.monotonic()
        while time.monotonic() - t0 < 30:
            line = self.proc.stderr.readline()
            if "DevTools listening on ws://" in line:
                port = int(line.split("ws://", 1)[1].split("/", 1)[0].rsplit(":", 1)[1])
                break
            if not line and self.proc.poll() is not None:
                break
        if port is None:
            self.close()
            raise RuntimeError("chromium did not start its DevTools endpoint")
        self.port = port

    def _new_target(self) -> dict:
        req = urllib.request.Request(f"http://127.0.0.1:{self.port}/json/new?about:blank", method="PUT")
        with urllib.request.urlopen(req, timeout=10) as r:
            return json.loads(r.read())

    def load(self, path: Path, timeout: float = 60.0) -> dict:
        target = self._new_target()
        ws = self._ws_mod.create_connection(
            target["webSocketDebuggerUrl"], timeout=timeout, suppress_origin=True
        )
        msg_id = 0
        events: list[dict] = []

        def call(method, **params):
            nonlocal msg_id
            msg_id += 1
            ws.send(json.dumps({"id": msg_id, "method": method, "params": params}))
            while True:
                m = json.loads(ws.recv())
                if m.get("id") == msg_id:
                    if "error" in m:
                        raise RuntimeError(f"{method}: {m['error']}")
                    return m.get("result", {})
                events.append(m)

        try:
            for dom in ("Runtime", "Log", "Network", "Page"):
                call(f"{dom}.enable")
            call(
                "Network.emulateNetworkConditions",
                offline=True,
                latency=0,
                downloadThroughput=-1,
                uploadThroughput=-1,
            )
            t0 = time.monotonic()
            call("Page.navigate", url=path.resolve().as_uri())
            state = None
            while time.monotonic() - t0 < timeout:
                r = call(
                    "Runtime.evaluate",
                    returnByValue=True,
                    expression=(
                        "JSON.stringify({rendered: document.body ?"
                        " document.body.dataset.fdikitRendered || null : null,"
                        " errors: (window.__fdikitErrors || []),"
                        " plots: Array.from(document.querySelectorAll('div.plot')).map(d => ({id: d.id,"
                        "   svg: d.querySelectorAll('svg.main-svg').length,"
                        "   xtitle: (d.querySelector('.g-xtitle') || {}).textContent || '',"
                        "   traces: (d.data || []).length, width: d.getBoundingClientRect().width,"
                        "   section: ((d.closest('section') || {querySelector: () => null})"
                        "     .querySelector('h2') || {}).textContent || ''}))})"
                    ),
                )
                state = json.loads(r["result"]["value"])
                if state["rendered"] is not None:
                    break
                time.sleep(0.1)
            state["seconds"] = time.monotonic() - t0
            time.sleep(0.2)
            call("Runtime.evaluate", expression="1")  # drain the events that arrived meanwhile
            state["console_errors"] = [
                e["params"]
                for e in events
                if (
                    e.get("method") == "Runtime.consoleAPICalled"
                    and e["params"].get("type") in ("error", "assert")
                )
                or e.get("method") == "Runtime.exceptionThrown"
                or (e.get("method") == "Log.entryAdded" and e["params"]["entry"].get("level") == "error")
            ]
            state["requests"] = [
                e["params"]["request"]["url"]
                for e in events
                if e.get("method") == "Network.requestWillBeSent"
            ]
            return state
        finally:
            ws.close()
            try:
                urllib.request.urlopen(
                    urllib.request.Request(
                        f"http://127.0.0.1:{self.port}/json/close/{target['id']}", method="PUT"
                    ),
                    timeout=5,
                ).close()
            except OSError:
                pass

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
        shutil.rmtree(self.profile, ignore_errors=True)


@pytest.fixture(scope="module")
def browser():
    if CHROMIUM is None:
        pytest.skip(
            "no Chromium on this machine (apt-get install chromium; .ci/run installs it where it can)"
        )
    pytest.importorskip("websocket", reason="websocket-client is not installed (pip install '.[test]')")
    b = Browser(CHROMIUM)
    yield b
    b.close()


def _check(state: dict, path: Path, min_plots: int) -> None:
    assert state["rendered"] is not None, f"{path.name}: the plots did not finish rendering: {state}"
    assert state["errors"] == [], f"{path.name}: script errors {state['errors']}"
    assert state["console_errors"] == [], f"{path.name}: console errors {state['console_errors'][:3]}"
    off = [u for u in state["requests"] if not u.startswith(("file:", "data:", "about:", "blob:"))]
    assert off == [], f"{path.name}: the page asked the network for {off[:5]}"
    plots = state["plots"]
    assert len(plots) >= min_plots and int(state["rendered"]) == len(plots), (
        path.name,
        len(plots),
        state["rendered"],
    )
    for p in plots:
        assert p["svg"] >= 1 and p["traces"] >= 1 and p["width"] > 100, f"{path.name}: plot {p} not rendered"


# ------------------------------------------------------------------------------------- reports
@pytest.fixture(scope="module")
def reports(tmp_path_factory):
    """One report of each kind, made quickly (the slow kinds have their own tests below)."""
    from fdikit import Signals
    from fdikit.faults import Bias
    from fdikit.monitor import Decision, Monitor
    from fdikit.report import campaign_report, monitor_report, roc_curve
    from fdikit.residuals import ObserverResidual
    from fdikit.systems import two_mass

    d = tmp_path_factory.mktemp("reports")
    designs = two_mass.design({"seed": 0, "runs": 60})
    gen = ObserverResidual(designs["observer"])
    hold = designs["hold"]
    mon = Monitor([gen], [hold], Decision(hold.output_names), on_invalid="hold")
    sig = two_mass.record([Bias("sensor:pos2", 0.02, start=6.0)], 1, 3, duration=12.0)
    v = sig.values.copy()
    v[0, 300:320, 0] = np.nan  # a gap: held and shaded
    sig = Signals(sig.t, v, sig.names, ["N", "m", "m"], check=False)
    res = mon.run(sig)
    out = {"monitor": (monitor_report(d / "monitor.html", signals=sig, result=res, monitor=mon), 4)}
    rng = np.random.default_rng(0)
    camp = {
        "snr_db": 23.0,
        "runs": {"F0": 20, "F1": 10},
        "pf": {"T1": 0.0, "T2": 0.05},
        "pd": {"F1": {"T1": 0.9, "T2": 0.4}, "F2": {"T1": 0.1, "T2": 1.0}},
        "dmatrix": {
            "faults": ["F0", "F1", "F2"],
            "tests": ["T1", "T2"],
            "d": [[0, 0], [1, 0], [0, 1]],
            "pd": [[0, 0.05], [0.9, 0.4], [0.1, 1.0]],
        },
        "confusion": {"F0": {"F0": 19, "F1": 1}, "F1": {"F1": 9, "F0": 1}, "F2": {"F2": 10}},
        "sensitivity": 0.95,
        "specificity": 0.95,
        "detection_time_histogram": {"edges": [0, 1, 2, 3], "counts": {"F1": [1, 5, 4], "F2": [6, 3, 1]}},
        "roc": {"T1": roc_curve(rng.normal(0, 1, 200), rng.normal(2, 1, 200))},
    }
    out["campaign"] = (campaign_report(camp, d / "campaign.html"), 5)
    return out


@pytest.mark.parametrize("kind", ["monitor", "campaign"])
def test_report_renders_offline(browser, reports, kind):
    path, n = reports[kind]
    _check(browser.load(path), path, n)


def test_report_command_renders_offline(browser, tmp_path):
    """``fdikit example-log`` -> ``fdikit monitor --events --stats`` -> ``fdikit report``, in the browser."""
    from fdikit.cli import main
    from fdikit.commands.example_log import write_example_logs
    from fdikit.monitor.config import load_config

    cfg = load_config(ROOT / "examples" / "two-mass" / "monitor.toml")
    if not (cfg.artifacts / "observer.json").exists():
        assert main(["design", str(cfg.path), "--json"]) == 0
    logs = write_example_logs(cfg.path, tmp_path, nominal=False)["logs"]
    ev, st = tmp_path / "ev.jsonl", tmp_path / "st.parquet"
    assert (
        main(
            [
                "monitor",
                logs["fault"],
                "--config",
                str(cfg.path),
                "--events",
                str(ev),
                "--stats",
                str(st),
                "--json",
            ]
        )
        == 0
    )
    out = tmp_path / "r.html"
    assert (
        main(
            [
                "report",
                str(out),
                "--events",
                str(ev),
                "--stats",
                str(st),
                "--log",
                logs["fault"],
                "--config",
                str(cfg.path),
            ]
        )
        == 0
    )
    _check(browser.load(out), out, 4)


def test_reconstruct_report_renders_offline(browser, tmp_path):
    from fdikit.cli import main

    out = tmp_path / "aircraft.html"
    assert (
        main(["reconstruct", "aircraft", "--t-final", "3", "--h", "1e-4", "--report", str(out), "--json"])
        == 0
    )
    _check(browser.load(out), out, 2)


@pytest.mark.skipif(not (RAV4 / "drive.blf").exists(), reason=f"the RAV4 minute is absent ({RAV4})")
def test_rav4_monitor_log_report_renders_offline(browser, tmp_path):
    from fdikit.cli import main

    out = tmp_path / "rav4.html"
    assert (
        main(
            ["car", "monitor-log", str(RAV4), "--inject", "yaw_rate:0.03@40", "--report", str(out), "--json"]
        )
        == 0
    )
    _check(browser.load(out), out, 4)


@pytest.mark.slow
def test_demo_and_scenario_reports_render_offline(browser, tmp_path):
    from fdikit.cli import main

    out = tmp_path / "scenario.html"
    assert main(["car", "scenario", "steering_actuator", "--report", str(out), "--json"]) == 0
    _check(browser.load(out), out, 4)
    demo = tmp_path / "demo.html"
    assert main(["demo", "--json", "--report", str(demo)]) == 0
    state = browser.load(demo)
    _check(state, demo, 6)
    # every section of the demo has a rendered plot, in its own section or a "<name>: ..." one
    from fdikit.commands.demo import sections

    titles = [p["section"].lower() for p in state["plots"] if p["svg"] >= 1]
    bare = [n for n in sections() if not any(t == n or t.startswith(f"{n}:") for t in titles)]
    assert bare == [], f"demo sections without a rendered plot: {bare}"


def test_the_check_itself_fails_on_errors_and_network(browser, tmp_path):
    """The browser check is not one that cannot fail: a page that logs an error, fetches from the
    network and never finishes rendering is caught on all three counts."""
    bad = tmp_path / "bad.html"
    bad.write_text(
        "<!DOCTYPE html><html><body><div class='plot' id='p1'></div>"
        "<img src='http://plotly-cdn.invalid/x.png'><script>console.error('boom');</script></body></html>"
    )
    state = browser.load(bad, timeout=3)
    assert state["rendered"] is None
    assert any("boom" in json.dumps(e) for e in state["console_errors"])
    assert any(u.startswith("http://plotly-cdn.invalid") for u in state["requests"])
    with pytest.raises(AssertionError):
        _check(state, bad, 1)
