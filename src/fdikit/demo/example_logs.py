"""Simulated logs to run an example monitor on (what ``fdikit example-log CONFIG --out DIR`` writes).

For each example config in ``examples/`` (chosen by its ``[design].recipe``) it simulates the
system the config monitors and writes, in the config's log format (CSV, the ``[log].time``
column, the *source* channel names and units, i.e. each monitor channel mapped back through
``(value + offset) / scale``):

* ``DIR/nominal.csv`` -- a fault-free record;
* ``DIR/fault.csv`` -- the same manoeuvre with a fault (``--fault``; a default per system);

so that ``fdikit monitor DIR/fault.csv --config CONFIG`` runs as the README says, after
``fdikit design CONFIG``. The RAV4 config reads the real CAN log in ``../shared/data`` and has
nothing to simulate.

The simulators (:data:`SYSTEMS`) compose the papers' systems, which is why this lives above them,
beside the demo, and not in the core.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import DataError

__all__ = ["SYSTEMS", "write_example_logs"]


def _parse_bias(spec: str, default_start: float) -> tuple[str, float, float]:
    m = re.fullmatch(r"\s*([A-Za-z_:.0-9]+):([-+0-9.eE]+)(?:@([0-9.eE+]+))?\s*", spec)
    if not m:
        raise DataError(f"bad --fault {spec!r}: use TARGET:MAGNITUDE[@START_S], e.g. sensor:pos2:0.012@4")
    return m.group(1), float(m.group(2)), float(m.group(3)) if m.group(3) else default_start


# ------------------------------------------------------------------------------------ systems
def _two_mass(fault: str | None, seed: int, duration: float | None, params: dict):
    from ..faults import Bias
    from ..systems import two_mass

    dur = duration or 10.0
    faults = []
    info = None
    if fault is not None:
        target, mag, start = _parse_bias(fault, 4.0)
        faults = [Bias(target, mag, start=start)]
        info = {"fault": target, "kind": "bias", "magnitude": mag, "onset_s": start}
    sig = two_mass.record(faults, 1, seed, duration=dur)
    from ..signals import Signals

    return Signals(sig.t, sig.values, sig.names, ["N", "m", "m"], check=False), info


def _abs(fault: str | None, seed: int, duration: float | None, params: dict):
    from ..systems.abs.plant import Scenario, simulate

    cls, mag = "F0", None
    if fault is not None:
        cls, _, m = fault.partition(":")
        mag = float(m) if m else None
    sc = Scenario(
        fault=cls,
        magnitude=mag,
        snr_db=params.get("snr_db", 23.0),
        **({"t_end": float(duration)} if duration else {}),
    )
    res = simulate(None, sc, runs=1, seed=seed)
    info = None
    if fault is not None:
        info = {
            "fault": cls,
            "kind": "fault class (luo-et-al Table II)",
            "magnitude": float(res.magnitudes[0]),
            "onset_s": 0.0,
        }
    return res.y.concat_channels(res.u), info


def _aircraft(fault: str | None, seed: int, duration: float | None, params: dict):
    from ..residuals.smo import simulate_plant
    from ..signals import Signals
    from ..systems.aircraft import plant as aircraft
    from ..systems.aircraft.reconstruction import X0

    h = float(params.get("dt", 1e-4))
    t_final = duration or 10.0
    t = np.arange(round(t_final / h) + 1) * h
    f = np.zeros_like(t)
    info = None
    if fault is not None:
        if fault not in ("rudder", "actuator:rudder_cmd"):
            raise DataError(
                f"the aircraft example has one fault, 'rudder' (the rudder actuator), got {fault!r}"
            )
        f = aircraft.fault_signal(t)
        info = {
            "fault": "actuator:rudder_cmd",
            "kind": "ramp from 2 s to 0.2 rad at 6 s, then a sine",
            "onset_s": 2.0,
        }
    Y = simulate_plant(aircraft.true_A("consistent"), aircraft.M, aircraft.C, f[:, None], h, x0=X0)
    Y = np.asarray(Y)[0] if np.asarray(Y).ndim == 3 else np.asarray(Y)
    U = np.zeros((t.size, len(aircraft.INPUTS)))
    return Signals(
        t,
        np.column_stack([U, Y]),
        [*aircraft.INPUTS, *aircraft.OUTPUTS],
        ["rad", "rad", "rad", "rad/s", "rad/s"],
        check=False,
    ), info


def _car(fault: str | None, seed: int, duration: float | None, params: dict):
    from ..faults import Bias
    from ..systems.car.driving import simulate_drive
    from ..systems.car.monitor import car_signals, sensor_noise

    speed = float(params.get("speed", 20.0))
    dur = duration or 14.0
    faults = []
    info = None
    if fault is not None:
        target, mag, start = _parse_bias(fault, 8.0)
        faults = [Bias(target, mag, start=start)]
        info = {"fault": target, "kind": "bias", "magnitude": mag, "onset_s": start}
    from ..signals import Signals
    from ..systems.car.recipe import operating_point

    res = simulate_drive(
        "straight", speed, duration=dur, faults=faults, seed=seed, dt=2.5e-3, noise=sensor_noise()
    )
    sig = car_signals(res)   # absolute values; the monitor channels are deviations from the trim
    op = operating_point(speed)
    trim = np.array([op.get(n, 0.0) for n in sig.names])
    return Signals(sig.t, sig.values - trim, sig.names, sig.units, check=False), info


#: recipe -> (simulator, default fault, description). A simulator returns monitor-channel Signals.
SYSTEMS: dict[str, tuple[Callable[..., Any], str, str]] = {
    "fdikit.systems.two_mass:design": (_two_mass, "sensor:pos2:0.012@4", "two-mass plant, sine force, 10 s"),
    "fdikit.systems.abs.recipe:design": (_abs, "F2.2:-0.25", "ABS braking stop from 28 m/s, 12.5 s"),
    "fdikit.systems.aircraft:design": (_aircraft, "rudder", "aircraft, zero commands, 10 s at 1e-4 s"),
    "fdikit.systems.car.recipe:design": (
        _car,
        "sensor:a_x:0.6@8",
        "passenger car, straight road at the design speed, 14 s",
    ),
}


def _to_source(cfg, sig) -> tuple[list[str], np.ndarray]:
    """Monitor channels back to the log's source columns: ``(value + offset) / scale``."""
    cols: dict[str, np.ndarray] = {}
    for c in cfg.channels:
        if c.name not in sig.names:
            raise DataError(
                f"{cfg.path}: the simulated system has no channel {c.name!r} (it has {sig.names})"
            )
        v = (sig[c.name][0] + c.offset) / c.scale
        if c.source in cols and not np.allclose(cols[c.source], v):
            raise DataError(f"{cfg.path}: source {c.source!r} maps to two different channels")
        cols[c.source] = v
    return list(cols), np.column_stack(list(cols.values()))


def write_example_logs(
    config: str | Path,
    out: str | Path,
    *,
    fault: str | None = None,
    seed: int = 0,
    duration: float | None = None,
    nominal: bool = True,
) -> dict[str, Any]:
    """Simulate and write the example logs of one config (see the module docstring).

    Parameters
    ----------
    config : str or Path
        An example monitor configuration (TOML) whose ``[design].recipe`` is a key of :data:`SYSTEMS`.
    out : str or Path
        Folder to write ``nominal.csv`` and ``fault.csv`` into (created).
    fault : str, optional
        The fault of ``fault.csv`` (default: the system's, :data:`SYSTEMS`).
    seed : int
        Random seed of the simulated noise.
    duration : float, optional
        Simulated time, s (default: the system's).
    nominal : bool
        Also write ``nominal.csv``.

    Returns
    -------
    dict
        ``config``, ``system``, ``logs`` {``nominal``, ``fault``: path}, ``fault`` (what was
        injected), ``samples``, ``sample_time_s``, ``time_column``, ``columns``, ``seed``,
        ``commands`` (to run next).

    Raises
    ------
    DataError
        For a CAN-log config, a recipe without a simulator, a bad fault or an ``out`` that is a file.
    """
    from ..io.write import write_csv
    from ..monitor.config import load_config
    from ..signals import Signals

    cfg = load_config(config)
    recipe = cfg.design.get("recipe")
    if cfg.log.get("dbc") or cfg.log.get("format") in ("can", "blf", "asc", "candump"):
        raise DataError(
            f"{cfg.path}: this monitor reads a CAN log ([log].dbc); there is nothing to simulate: run "
            "it on the recorded log (for the RAV4: ../shared/data/rav4-highway/drive.blf)"
        )
    if recipe not in SYSTEMS:
        raise DataError(
            f"{cfg.path}: no example simulator for the design recipe {recipe!r}; known: {sorted(SYSTEMS)}"
        )
    sim, default_fault, what = SYSTEMS[recipe]
    outdir = Path(out)
    if outdir.exists() and not outdir.is_dir():
        raise DataError(f"{outdir}: exists and is not a folder")
    outdir.mkdir(parents=True, exist_ok=True)
    params = dict(cfg.design.get("params", {}))
    tcol = cfg.log.get("time", "t")
    logs: dict[str, str] = {}
    injected = None
    n = dt = None
    names: list[str] = []
    for kind, spec in (("nominal", None), ("fault", fault or default_fault)):
        if kind == "nominal" and not nominal:
            continue
        sig, info = sim(spec, seed, duration, params)
        names, cols = _to_source(cfg, sig)
        path = write_csv(Signals(sig.t, cols, names, check=False), outdir / f"{kind}.csv", time=tcol)
        logs[kind] = str(path)
        n, dt = sig.n_samples, sig.dt
        if info is not None:
            injected = info
    commands = [f"fdikit design {cfg.path}"] + [
        f"fdikit monitor {p} --config {cfg.path} --events {outdir / (k + '-events.jsonl')} "
        f"--stats {outdir / (k + '-stats.parquet')} --json"
        for k, p in logs.items()
    ]
    return {
        "config": str(cfg.path),
        "system": what,
        "logs": logs,
        "fault": injected,
        "samples": n,
        "sample_time_s": dt,
        "time_column": tcol,
        "columns": names,
        "seed": seed,
        "commands": commands,
    }
