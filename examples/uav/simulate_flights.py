"""Simulated fixed-wing UAV flights written as PX4 ULog files: nominal flights and engine failures.

The airframe is a small fixed-wing's linearised longitudinal dynamics about straight, level
cruise at 20 m/s (states: forward speed u, vertical speed w, pitch rate q, pitch theta, altitude
h; inputs: elevator (rad) and throttle (0..1)). An autopilot flies it at 50 Hz (airspeed on the
throttle, altitude through a pitch command on the elevator, a pitch damper) through a schedule of
airspeed and altitude set-points, with a small dither on both commands (identification
manoeuvres). Turbulence (first-order gusts along and across the flight path) and sensor noise
make it realistic.

An **engine failure** removes the thrust at a known time: the throttle is still commanded (and
logged; the autopilot pushes it to full), the propeller no longer pulls.

Each flight is one ULog file of multi-rate topics, as PX4 logs them:

=================================  =======  ===============================================
topic.field                        rate     meaning
=================================  =======  ===============================================
``actuator_controls_0.elevator``   50 Hz    elevator command (rad, positive trailing edge down)
``actuator_controls_0.throttle``   50 Hz    throttle command (0..1)
``vehicle_angular_velocity.q``     50 Hz    pitch rate (rad/s), IMU
``vehicle_attitude.pitch``         50 Hz    pitch angle (rad), attitude estimator
``airspeed.true_airspeed_m_s``     10 Hz    true airspeed (m/s), pitot
``vehicle_gps_position.alt``       5 Hz     altitude (m), GPS
=================================  =======  ===============================================

Usage::

    python examples/uav/simulate_flights.py OUT_DIR [--nominal 8] [--failures 3] [--duration 120]

writes ``OUT_DIR/nominal_NN.ulg`` and ``OUT_DIR/failure_NN.ulg`` and ``OUT_DIR/flights.json``
(each flight's seed, duration and engine-failure time).
"""

from __future__ import annotations

import argparse
import json
import struct
from pathlib import Path

import numpy as np
import scipy.linalg as sla

#: Cruise airspeed (m/s), gravity (m/s^2), trim throttle and elevator.
U0, G, THROTTLE_TRIM, ELEVATOR_TRIM = 20.0, 9.81, 0.55, -0.04
#: Thrust acceleration per unit throttle (m/s^2).
X_THROTTLE = 6.0
#: Physics step (s) and autopilot / IMU step (s).
DT_SIM, DT_AP = 0.01, 0.02
#: Topics: name -> (period in physics steps, fields).
TOPICS = {
    "actuator_controls_0": (2, ("elevator", "throttle")),
    "vehicle_angular_velocity": (2, ("q",)),
    "vehicle_attitude": (2, ("pitch",)),
    "airspeed": (10, ("true_airspeed_m_s",)),
    "vehicle_gps_position": (20, ("alt",)),
}
#: Sensor noise standard deviations.
NOISE = {"q": 0.01, "pitch": 0.004, "true_airspeed_m_s": 0.25, "alt": 0.4}


def airframe() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Continuous longitudinal model ``x' = A x + B [elevator, throttle] + E [u_gust, w_gust]``.

    Returns
    -------
    A : ndarray (5, 5)
        States ``u`` (m/s), ``w`` (m/s, down), ``q`` (rad/s), ``theta`` (rad), ``h`` (m).
    B : ndarray (5, 2)
        Inputs: elevator deviation (rad), throttle deviation (1).
    E : ndarray (5, 2)
        Gusts along and across the flight path (m/s): aerodynamic forces act on the airspeed
        relative to the air.
    """
    Xu, Xw, Zu, Zw, Mu, Mw, Mq = -0.15, 0.25, -0.9, -4.0, 0.0, -1.6, -5.0
    A = np.array([[Xu, Xw, 0.0, -G, 0.0],
                  [Zu, Zw, U0, 0.0, 0.0],
                  [Mu, Mw, Mq, 0.0, 0.0],
                  [0.0, 0.0, 1.0, 0.0, 0.0],
                  [0.0, -1.0, 0.0, U0, 0.0]])
    B = np.array([[0.0, X_THROTTLE], [-2.0, 0.0], [-28.0, 0.0], [0.0, 0.0], [0.0, 0.0]])
    E = np.zeros((5, 2))
    E[:3, :] = -A[:3, :2]
    return A, B, E


def _discrete(dt: float):
    A, B, E = airframe()
    n, m = A.shape[0], B.shape[1] + E.shape[1]
    M = np.zeros((n + m, n + m))
    M[:n, :n], M[:n, n:] = A, np.c_[B, E]
    Phi = sla.expm(M * dt)
    return Phi[:n, :n], Phi[:n, n:n + 2], Phi[:n, n + 2:]


def simulate_flight(seed: int, duration: float = 120.0, failure_at: float | None = None,
                    thrust_left: float = 0.0) -> dict[str, tuple[np.ndarray, dict[str, np.ndarray]]]:
    """One flight: topics ``name -> (timestamps in us since boot, {field: values})``.

    Parameters
    ----------
    seed : int
        Random seed (turbulence, noise, set-points, dither).
    duration : float
        Flight length logged (s).
    failure_at : float, optional
        Engine failure time (s after the log starts): from then the thrust is ``thrust_left``
        times the commanded one.
    thrust_left : float
        Fraction of the thrust left after the failure (0: none).
    """
    rng = np.random.default_rng(seed)
    Ad, Bd, Ed = _discrete(DT_SIM)
    n = round(duration / DT_SIM)
    boot_us = 5_000_000 + int(rng.integers(0, 1_000_000))     # the log starts a few seconds after boot
    # set-points: a new airspeed and altitude every 12-25 s
    v_sp, h_sp = np.empty(n), np.empty(n)
    k = 0
    while k < n:
        span = int(rng.uniform(12.0, 25.0) / DT_SIM)
        v_sp[k:k + span] = U0 + rng.uniform(-2.5, 2.5)
        h_sp[k:k + span] = 100.0 + rng.uniform(-15.0, 15.0)
        k += span
    v_sp[: int(5 / DT_SIM)], h_sp[: int(5 / DT_SIM)] = U0, 100.0
    # turbulence: first-order gusts (sigma 0.6 / 0.4 m/s, time constants 4 / 1.5 s)
    gust = np.zeros(2)
    a_g = np.exp(-DT_SIM / np.array([4.0, 1.5]))
    s_g = np.array([0.6, 0.4]) * np.sqrt(1 - a_g ** 2)
    x = np.array([0.0, 0.0, 0.0, 0.0, 100.0 - 100.0])           # deviations; altitude about 100 m
    ap = {"iv": 0.0, "ih": 0.0, "cmd": np.array([ELEVATOR_TRIM, THROTTLE_TRIM])}
    logs: dict[str, list] = {name: [] for name in TOPICS}
    dither = np.zeros(2)
    for k in range(n):
        t = k * DT_SIM
        meas = {"q": x[2] + rng.normal(0, NOISE["q"]), "pitch": x[3] + rng.normal(0, NOISE["pitch"]),
                "true_airspeed_m_s": U0 + x[0] - gust[0] + rng.normal(0, NOISE["true_airspeed_m_s"]),
                "alt": 100.0 + x[4] + rng.normal(0, NOISE["alt"])}
        if k % 2 == 0:                                          # the autopilot at 50 Hz
            if k % 25 == 0:                                     # dither: a new random level every 0.25 s
                dither = rng.normal(0, [0.015, 0.03])
            ev = v_sp[k] - meas["true_airspeed_m_s"]
            eh = h_sp[k] - meas["alt"]
            ap["iv"] = float(np.clip(ap["iv"] + ev * DT_AP, -3.0, 3.0))
            ap["ih"] = float(np.clip(ap["ih"] + eh * DT_AP, -30.0, 30.0))
            theta_c = float(np.clip(0.012 * eh + 0.001 * ap["ih"], -0.25, 0.25))
            elev = ELEVATOR_TRIM + 0.6 * (meas["pitch"] - theta_c) + 0.08 * meas["q"] + dither[0]
            thr = THROTTLE_TRIM + 0.08 * ev + 0.04 * ap["iv"] + dither[1]
            ap["cmd"] = np.array([np.clip(elev, -0.4, 0.4), np.clip(thr, 0.0, 1.0)])
        for name, (period, fields) in TOPICS.items():
            if k % period == 0:
                vals = {"elevator": ap["cmd"][0], "throttle": ap["cmd"][1], **meas}
                logs[name].append((t, [vals[f] for f in fields]))
        thrust = ap["cmd"][1] * (thrust_left if failure_at is not None and t >= failure_at else 1.0)
        u_dev = np.array([ap["cmd"][0] - ELEVATOR_TRIM, thrust - THROTTLE_TRIM])
        x = Ad @ x + Bd @ u_dev + Ed @ gust
        gust = a_g * gust + s_g * rng.normal(size=2)
    out = {}
    for name, (_, fields) in TOPICS.items():
        t = np.array([r[0] for r in logs[name]])
        jitter = rng.integers(0, 400, t.size)                   # up to 0.4 ms of logging jitter
        ts = boot_us + np.round(t * 1e6).astype(np.int64) + jitter + 100
        v = np.array([r[1] for r in logs[name]], dtype=np.float32)
        out[name] = (ts.astype(np.uint64), {f: v[:, i] for i, f in enumerate(fields)})
    out["_start_us"] = boot_us                                  # type: ignore[assignment]
    return out


def write_ulog(path: str | Path, topics: dict, start_us: int) -> Path:
    """Write topics as a ULog file (format version 1: header, flag bits, formats, subscriptions,
    data messages in time order; every field a float32 after the uint64 ``timestamp``).

    Parameters
    ----------
    path : path-like
        The ``.ulg`` file to write.
    topics : dict
        ``name -> (timestamps (N,) uint64 us since boot, {field: (N,) values})``.
    start_us : int
        The log's start (us since boot), in the file header.
    """

    def msg(kind: str, body: bytes) -> bytes:
        return struct.pack("<HB", len(body), ord(kind)) + body

    out = bytearray(b"ULog\x01\x12\x35\x01" + struct.pack("<Q", int(start_us)))
    out += msg("B", bytes(40))                                  # flag bits: no incompatible flags
    for name, (_, fields) in topics.items():
        spec = f"{name}:uint64_t timestamp;" + "".join(f"float {f};" for f in fields)
        out += msg("F", spec.encode())
    stamps, blobs = [], []
    for msg_id, (name, (ts, fields)) in enumerate(topics.items()):
        out += msg("A", struct.pack("<BH", 0, msg_id) + name.encode())
        dt = np.dtype([("size", "<u2"), ("type", "u1"), ("id", "<u2"), ("ts", "<u8"),
                       ("v", "<f4", (len(fields),))])
        rec = np.zeros(len(ts), dt)
        rec["size"], rec["type"], rec["id"], rec["ts"] = dt.itemsize - 3, ord("D"), msg_id, ts
        rec["v"] = np.column_stack([np.asarray(v, np.float32) for v in fields.values()])
        stamps.append(np.asarray(ts, np.uint64))
        blobs.extend(bytes(r) for r in rec)
    order = np.argsort(np.concatenate(stamps), kind="stable")
    out += b"".join(blobs[i] for i in order)
    path = Path(path)
    path.write_bytes(bytes(out))
    return path


def write_flights(out_dir: str | Path, nominal: int = 8, failures: int = 3, duration: float = 120.0,
                  seed: int = 0, failure_window: tuple[float, float] = (0.4, 0.7)) -> dict:
    """Simulate and write ``nominal`` nominal flights and ``failures`` engine failures.

    Parameters
    ----------
    out_dir : path-like
        Folder for ``nominal_NN.ulg``, ``failure_NN.ulg`` and ``flights.json``.
    nominal, failures : int
        Numbers of flights.
    duration : float
        Each flight's length (s).
    seed : int
        Base seed (flight ``i`` uses ``seed * 1000 + i``).
    failure_window : (float, float)
        The failure time is drawn uniformly in this fraction of the flight.

    Returns
    -------
    dict
        ``{"flights": [{"file", "seed", "duration", "failure_at"}, ...]}`` (also in ``flights.json``).
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    flights = []
    for i in range(nominal + failures):
        fail = None if i < nominal else float(np.round(rng.uniform(*failure_window) * duration, 2))
        name = f"nominal_{i:02d}.ulg" if fail is None else f"failure_{i - nominal:02d}.ulg"
        s = seed * 1000 + i
        topics = simulate_flight(s, duration, fail)
        start = topics.pop("_start_us")
        write_ulog(out_dir / name, topics, start)
        flights.append({"file": name, "seed": s, "duration": duration, "failure_at": fail})
    meta = {"flights": flights}
    (out_dir / "flights.json").write_text(json.dumps(meta, indent=1))
    return meta


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("out_dir", help="folder for the .ulg files (created)")
    ap.add_argument("--nominal", type=int, default=8, help="nominal flights (default 8)")
    ap.add_argument("--failures", type=int, default=3, help="engine-failure flights (default 3)")
    ap.add_argument("--duration", type=float, default=120.0, help="seconds per flight (default 120)")
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args(argv)
    meta = write_flights(a.out_dir, a.nominal, a.failures, a.duration, a.seed)
    for f in meta["flights"]:
        print(f"{a.out_dir}/{f['file']}" + (f"  engine failure at {f['failure_at']} s" if f["failure_at"]
                                            else ""))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
