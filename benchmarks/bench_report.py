"""HTML report: size of a 1-hour log's report (target <= 10 MB) and time to generate the RAV4
minute's report (target <= 2 s); where Chromium is installed, also the time a headless browser
takes to open and render each page (target <= 3 s).

The 1-hour log is generated: the two-mass example plant (fdikit.systems.two_mass) at 100 Hz for
3600 s (360,001 samples), with a one-sample spike on pos1 at 900 s, a 10 s gap (NaN: held by the
monitor) from 1200 s and a pos2 sensor bias from 2400 s, run through the example's observer +
hold monitor. The RAV4 minute is ``../shared/data/rav4-highway/drive.blf`` through
``examples/rav4-lateral/monitor.toml`` (designed first when its artifacts are missing); the
report time is the time of :func:`fdikit.report.monitor_report` on the monitor's results (read,
decode and monitor are timed separately).

    python benchmarks/bench_report.py

Prints its figures and, as the last line, one JSON object.
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
RAV4 = ROOT.parent / "shared" / "data" / "rav4-highway"


def _open_seconds(path: Path) -> float | None:
    """Seconds from navigation until the page says all its plots are drawn, in headless Chromium
    over the DevTools protocol (the browser test's driver), offline; best of 2. None without
    Chromium or websocket-client."""
    sys.path.insert(0, str(ROOT / "tests"))
    try:
        import websocket  # noqa: F401
        from test_report_browser import CHROMIUM, Browser
    except ImportError:
        return None
    if CHROMIUM is None:
        return None
    b = Browser(CHROMIUM)
    try:
        times = []
        for _ in range(2):
            st = b.load(path, timeout=120)
            if st["rendered"] is None or st["errors"] or st["console_errors"]:
                return None
            times.append(st["seconds"])
        return round(min(times), 2)
    finally:
        b.close()


def one_hour(tmp: Path) -> dict:
    from fdikit import Signals
    from fdikit.faults import Bias
    from fdikit.monitor import Decision, Monitor
    from fdikit.report import monitor_report
    from fdikit.residuals import ObserverResidual
    from fdikit.systems import two_mass

    t0 = time.perf_counter()
    designs = two_mass.design({"runs": 100})
    gen = ObserverResidual(designs["observer"])
    hold = designs["hold"]
    names = {"r:pos1:alarm": "sensor:pos1", "r:pos2:alarm": "sensor:pos2"}
    mon = Monitor([gen], [hold], Decision(hold.output_names, names=names), on_invalid="hold")
    sig = two_mass.record([Bias("sensor:pos2", 0.012, start=2400.0)], 1, 5, duration=3600.0)
    v = sig.values.copy()
    k_spike = round(900.0 / two_mass.DT)
    v[0, k_spike, 1] += 0.5  # one-sample spike (m) on pos1
    gap = (sig.t >= 1200.0) & (sig.t < 1210.0)
    v[0, gap, 2] = np.nan
    sig = Signals(sig.t, v, sig.names, ["N", "m", "m"], check=False)
    t_sim = time.perf_counter() - t0
    t1 = time.perf_counter()
    res = mon.run(sig)
    t_mon = time.perf_counter() - t1
    path = tmp / "one_hour.html"
    t2 = time.perf_counter()
    monitor_report(path, signals=sig, result=res, monitor=mon, title="1-hour two-mass log")
    t_rep = time.perf_counter() - t2
    html = path.read_text()
    # the spike is in the page: the decimated pos1 trace keeps its maximum
    data = json.loads(html.split("id='fdikit-figures'>", 1)[1].split("</script>", 1)[0].replace("<\\/", "</"))
    import base64

    ymax = None
    for fig in data:
        for tr in fig["data"]:
            if tr.get("name") == "pos1" and isinstance(tr.get("y"), dict):
                y = np.frombuffer(base64.b64decode(tr["y"]["bdata"]), "<f4")
                ymax = float(np.nanmax(y))
    return {
        "samples": sig.n_samples,
        "channels_plotted": sig.n_channels + 2 * len(gen.output_names),
        "events": len(res.events),
        "held_samples": int((~res.valid).sum()),
        "report_bytes": path.stat().st_size,
        "report_mb": round(path.stat().st_size / 2**20, 3),
        "report_seconds": round(t_rep, 3),
        "simulate_seconds": round(t_sim, 3),
        "monitor_seconds": round(t_mon, 3),
        "spike_in_page_m": ymax,
        "spike_true_m": float(np.nanmax(v[0, :, 1])),
        "path": str(path),
    }


def rav4(tmp: Path) -> dict | None:
    if not (RAV4 / "drive.blf").exists():
        return None
    from fdikit import DataError
    from fdikit.monitor.config import build_monitor, load_config, map_channels, read_log, run_design
    from fdikit.report import monitor_report

    cfg = load_config(ROOT / "examples" / "rav4-lateral" / "monitor.toml")
    try:
        build_monitor(cfg)
    except DataError:  # never designed, or designed from another version of the config
        run_design(cfg)
    t0 = time.perf_counter()
    log = read_log(cfg, RAV4 / "drive.blf")
    sig = map_channels(cfg, log)
    mon = build_monitor(cfg)
    res = mon.run(sig)
    t_mon = time.perf_counter() - t0
    path = tmp / "rav4.html"
    times = []
    for _ in range(3):
        t1 = time.perf_counter()
        monitor_report(
            path,
            signals=sig,
            result=res,
            monitor=mon,
            config=cfg,
            log=RAV4 / "drive.blf",
            signal_valid=getattr(log, "valid", None),
        )
        times.append(time.perf_counter() - t1)
    return {
        "samples": sig.n_samples,
        "events": len(res.events),
        "report_seconds_best": round(min(times), 3),
        "report_seconds_first": round(times[0], 3),
        "read_and_monitor_seconds": round(t_mon, 3),
        "report_bytes": path.stat().st_size,
        "path": str(path),
    }


def main() -> dict:
    tmp = Path(tempfile.mkdtemp(prefix="fdikit-bench-report-"))
    out: dict = {"one_hour": one_hour(tmp), "rav4": rav4(tmp)}
    h = out["one_hour"]
    print(
        f"1-hour log ({h['samples']} samples): report {h['report_mb']} MB (target <= 10 MB) in "
        f"{h['report_seconds']} s; spike {h['spike_true_m']:.4f} m kept in the page as "
        f"{h['spike_in_page_m']:.4f} m"
    )
    h["open_seconds"] = _open_seconds(Path(h["path"]))
    if h["open_seconds"] is not None:
        print(f"  headless Chromium opens and renders it in {h['open_seconds']:.2f} s (target <= 3 s)")
    r = out["rav4"]
    if r is None:
        print(f"RAV4 minute absent ({RAV4}): skipped")
    else:
        print(
            f"RAV4 minute ({r['samples']} samples): report generated in {r['report_seconds_best']} s "
            f"best of 3 (first {r['report_seconds_first']} s; target <= 2 s), "
            f"{r['report_bytes'] / 2**20:.2f} MB; read, "
            f"decode and monitor {r['read_and_monitor_seconds']} s"
        )
        r["open_seconds"] = _open_seconds(Path(r["path"]))
        if r["open_seconds"] is not None:
            print(f"  headless Chromium opens and renders it in {r['open_seconds']:.2f} s")
    out["targets"] = {"one_hour_report_mb": 10.0, "rav4_report_seconds": 2.0, "open_seconds": 3.0}
    return out


if __name__ == "__main__":
    res = main()
    sys.stdout.write(json.dumps(res) + "\n")
