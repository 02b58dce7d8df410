"""Injection benchmark of the RAV4 sensor isolation and fault typing (issue 27, item 6; first version).

On the real minute's held-out half (onsets 35, 40, 45 s): every sensor x bias / drift / gain /
stuck / intermittent x both signs x three magnitudes. Prints the confusion matrices of the
component (the first announcement naming one sensor) and of the fault type (the type that
announcement settled on within 5 s), the delay distribution per type, false announcements on the
fault-free minute, before the onset and naming another sensor after it; and the same for a peer:
a per-signal Page-Hinkley on the raw signals (hand-written, river's form; tuned on 0-30 s of the
fault-free minute to zero alarms), which detects but names only the signal it runs on and no type.

Measured (300 runs, 2026-12; only "<sensor>:<type>" announcements count, the MHSSPT's untyped
ones do not): component right / wrong sensor / none -- peer checks: wheel_fl 72 / 0 / 3, wheel_rr
71 / 0 / 4, yaw_rate 49 / 0 / 26, lateral_accelerometer 59 / 0 / 16, no announcement naming another
sensor; issue-16 detectors (``--old``): wheel_fl 36 / 39 (wheel_fr) / 0, wheel_rr 36 / 39 (wheel_rl)
/ 0, yaw_rate 73 / 0 / 2, lateral_accelerometer 0 / 0 / 75, 93 announcements naming another sensor.
Type right (of 72 per type, stuck 12) -- peer checks: bias 56, drift 59, gain 11 (28 typed bias
within 5 s: the revision to gain comes later), intermittent 25, stuck 12; old: bias 0 (no bias
type), drift 18, gain 36, intermittent 30, stuck 0. No false announcement on the fault-free minute
nor before an onset, either way. Runtime: 96 s (old: 15 s).

Not yet here (issue 27, item 6): two-fault combinations, the artefacts, the detectability floor
per sensor and the second peer. Run: ``PYTHONPATH=src python benchmarks/bench_sensor_faults.py
[--quick] [--old]`` (``--old``: the issue-16 detectors, ``peer_checks=False``).
"""

from __future__ import annotations

import argparse
import collections
import time

import numpy as np

DATA = "../shared/data/rav4-highway"
SENSORS = {"wheel_fl": "WHEEL_SPEED_FL", "wheel_rr": "WHEEL_SPEED_RR", "yaw_rate": "YAW_RATE",
           "lateral_accelerometer": "ACCEL_Y"}
# per sensor and type: three magnitudes from small to large (DBC units; gain: the factor's offset from 1)
MAGS = {"WHEEL_SPEED_FL": {"bias": (0.5, 1.0, 2.0), "drift": (0.1, 0.2, 0.5), "gain": (0.01, 0.015, 0.03),
                           "intermittent": (1.0, 2.0, 4.0)},
        "WHEEL_SPEED_RR": {"bias": (0.5, 1.0, 2.0), "drift": (0.1, 0.2, 0.5), "gain": (0.01, 0.015, 0.03),
                           "intermittent": (1.0, 2.0, 4.0)},
        "YAW_RATE": {"bias": (0.5, 1.0, 2.0), "drift": (0.05, 0.1, 0.2), "gain": (0.5, 1.0, 2.0),
                     "intermittent": (1.0, 2.0, 4.0)},
        "ACCEL_Y": {"bias": (0.4, 0.8, 1.5), "drift": (0.05, 0.1, 0.2), "gain": (0.2, 0.5, 1.0),
                    "intermittent": (0.5, 1.0, 2.0)}}
_SENS = set(SENSORS) | {"wheel_fr", "wheel_rl", "steering"}


def page_hinkley(x, delta, lam, alpha=0.9999):
    """Two-sided Page-Hinkley (river's form) over x (T,): the first alarm index or None."""
    mean, n, up, lo = 0.0, 0, 0.0, 0.0
    for k, v in enumerate(x):
        n += 1
        mean += (v - mean) / n
        up = max(0.0, alpha * up + (v - mean - delta))
        lo = max(0.0, alpha * lo + (mean - v - delta))
        if up > lam or lo > lam:
            return k
    return None


def cases(quick):
    onsets = (40.0,) if quick else (35.0, 40.0, 45.0)
    for sensor, can in SENSORS.items():
        for typ, mags in MAGS[can].items():
            for m in (mags[1:2] if quick else mags):
                for sign in (1, -1):
                    for t0 in onsets:
                        if typ == "gain":
                            spec = f"gain:{can}:{1 + sign * m:g}@{t0:g}"
                        elif typ == "drift":
                            spec = f"drift:{can}:{sign * m:g}/s@{t0:g}"
                        elif typ == "intermittent":
                            spec = f"intermittent:{can}:{sign * m:g}@{t0:g}"
                        else:
                            spec = f"bias:{can}:{sign * m:g}@{t0:g}"
                        yield sensor, typ, m, sign, t0, spec
        for t0 in onsets:
            yield sensor, "stuck", 0.0, 1, t0, f"stuck:{can}@{t0:g}"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--old", action="store_true")
    a = ap.parse_args()
    from fdikit.systems.car.monitor_rav4 import RAW_SOURCES, inject, parse_inject, rav4_monitor, run_rav4_log

    kw = {"peer_checks": False} if a.old else {}
    t_start = time.time()
    nominal = run_rav4_log(DATA, "none", **kw)
    print(f"fault-free minute: {len(nominal['announcements'])} announcements {nominal['announcements']}")
    mon = rav4_monitor(DATA, **kw)
    raw, pre = mon.raw, mon.artifacts["filter"].pre
    t = raw.t - raw.t[0]
    # Page-Hinkley peer: per raw signal, lambda tuned on 0-30 s to zero alarms (x 1.2)
    chan = {s: next(n for n, v in RAW_SOURCES.items() if v[0].endswith("." + c)) for s, c in SENSORS.items()}
    ph = {}
    for s, c in chan.items():
        x = raw[c][0]
        d = 0.5 * float(np.std(np.diff(x)))
        lam = 1e-9
        while page_hinkley(x[t <= 30.0], d, lam) is not None:
            lam *= 1.5
        ph[s] = (d, lam * 1.2)
    comp = collections.defaultdict(collections.Counter)
    typ_cm = collections.defaultdict(collections.Counter)
    delays = collections.defaultdict(list)
    ph_comp = collections.defaultdict(collections.Counter)
    ph_delays = collections.defaultdict(list)
    before = wrong = 0
    n = 0
    for sensor, typ, _m, _sign, t0, spec in cases(a.quick):
        n += 1
        r = run_rav4_log(DATA, spec, **kw)
        named = []
        for e in r["announcements"]:
            s, _, ty = e["fault"].partition(":")
            if ty and s in _SENS:
                named.append((e["t"], s, ty))
        before += sum(1 for e in r["announcements"] if e["t"] < t0)
        after = [x for x in named if x[0] >= t0]
        wrong += sum(1 for x in after if x[1] != sensor)
        if after:
            comp[sensor][after[0][1]] += 1
            same = [x for x in after if x[1] == after[0][1] and x[0] <= after[0][0] + 5.0]
            typ_cm[typ][same[-1][2]] += 1
            delays[typ].append(after[0][0] - t0)
        else:
            comp[sensor]["(none)"] += 1
            typ_cm[typ]["(none)"] += 1
        # Page-Hinkley on every signal: the first to alarm after the onset is the one it names
        sig = inject(raw, parse_inject(spec), pre)
        first = None
        for s, c in chan.items():
            k = page_hinkley(sig[c][0], *ph[s])
            if k is not None and (first is None or k < first[0]):
                first = (k, s)
        if first is None or t[first[0]] < t0:
            ph_comp[sensor]["(none)" if first is None else "(before onset)"] += 1
        else:
            ph_comp[sensor][first[1]] += 1
            ph_delays[typ].append(t[first[0]] - t0)

    def show(title, cm):
        cols = sorted({c for row in cm.values() for c in row})
        print(f"\n{title}\n{'':24}" + "".join(f"{c[:12]:>13}" for c in cols))
        for k, row in cm.items():
            print(f"{k:24}" + "".join(f"{row.get(c, 0):>13}" for c in cols))

    print(f"\n{n} injected runs ({'issue-16 detectors' if a.old else 'peer checks + fault-type stage'}), "
          f"{time.time() - t_start:.0f} s")
    show("component (rows: injected; columns: first sensor named after the onset)", comp)
    show("fault type (rows: injected; columns: the type settled on within 5 s)", typ_cm)
    print("\ndelay of the first named announcement (s): type: n, median, 90 %")
    for k, v in delays.items():
        print(f"  {k:14} {len(v):3d} {np.median(v):7.2f} {np.percentile(v, 90):7.2f}")
    print(f"announcements before the onset: {before}; after it naming another sensor: {wrong}")
    show("Page-Hinkley peer, component (first signal to alarm)", ph_comp)
    print("Page-Hinkley delays (s): type: n, median")
    for k, v in ph_delays.items():
        print(f"  {k:14} {len(v):3d} {np.median(v):7.2f}")


if __name__ == "__main__":
    main()
