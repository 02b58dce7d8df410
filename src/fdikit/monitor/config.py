"""Config-driven monitors: a TOML file names the channels, the design artifacts, the processors and
the decision; designs are data produced once (``fdikit design``) and loaded by the runtime
(``fdikit monitor``) without changing code.

Schema (every key is checked: an unknown key or a wrong type is an error naming it)::

    [monitor]
    name = "two-mass"             # free text
    artifacts = "designs"         # directory of the design artifacts, relative to this file
    on_invalid = "hold"           # "hold" (flag bad samples, keep state) or "raise"

    [log]                         # how `fdikit monitor LOG` reads a recorded log
    format = "auto"               # "auto" (by extension), "csv" or "can"
    time = "t"                    # CSV time column
    dbc = "car.dbc"               # CAN logs: the DBC, relative to this file
    rate = 100.0                  # Hz: resample onto this grid (CAN logs need it)

    [channels.pos1]               # a monitor channel (the name the designs use)
    source = "POS.P1"             # the column / "MESSAGE.SIGNAL" in the log (default: the name)
    scale = 1.0                   # value = scale * source - offset
    offset = 0.0                  # nominal operating point to subtract (ng-chen-speyer, Section V)
    unit = "m"                    # unit after scaling (documentation, stored in artifacts)

    [design]                      # how `fdikit design CONFIG` makes the artifacts
    recipe = "package.module:function"   # function(params: dict) -> {artifact name: design}
    [design.params]               # passed to the recipe as a dict
    dt = 0.01

    [[generators]]                # residual generators, in order
    artifact = "observer"         # <artifacts>/observer.json (+ .npz)

    [[processors]]                # residual processors, in order
    artifact = "hold"

    [decision]                    # announcements
    channels = ["r:pos2:alarm"]
    level = 0.5
    names = { "r:pos2:alarm" = "sensor:pos2" }
"""

from __future__ import annotations

import importlib
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..base.artifacts import load_artifact, moved, save_artifact
from ..errors import DataError
from ..signals import Signals
from .core import Decision, Monitor

__all__ = ["ChannelMap", "MonitorConfig", "build_monitor", "load_config", "map_channels", "read_log",
           "run_design"]

#: Designs that need a runtime wrapper: artifact kind -> "module:class".
RUNTIMES = {
    "ObserverDesign": "fdikit.residuals.observer:ObserverResidual",
    "FilterDesign": "fdikit.residuals.fdf:FaultDetectionFilter",
}

_SCHEMA: dict[str, dict[str, type | tuple[type, ...]]] = {
    "monitor": {"name": str, "artifacts": str, "on_invalid": str},
    "log": {"format": str, "time": str, "dbc": str, "rate": (int, float)},
    "design": {"recipe": str, "params": dict, "sample_time": (int, float), "plant": dict, "faults": dict,
               "disturbances": dict, "noise": dict, "alarm": dict, "structure": dict},
    "decision": {"channels": list, "level": (int, float), "names": dict},
}
_CHANNEL_KEYS: dict[str, type | tuple[type, ...]] = {"source": str, "scale": (int, float),
                                                      "offset": (int, float), "unit": str}
_STAGE_KEYS: dict[str, type | tuple[type, ...]] = {"artifact": str}
_TOP = {"monitor", "log", "channels", "design", "generators", "processors", "decision"}


@dataclass
class ChannelMap:
    """One monitor channel: ``value = scale * log[source] - offset``."""

    name: str
    source: str
    scale: float = 1.0
    offset: float = 0.0
    unit: str = ""


@dataclass
class MonitorConfig:
    """A parsed, validated monitor configuration (see the module docstring for the schema)."""

    path: Path
    name: str
    artifacts: Path
    on_invalid: str
    channels: list[ChannelMap]
    generators: list[str]
    processors: list[str]
    log: dict[str, Any] = field(default_factory=dict)
    design: dict[str, Any] = field(default_factory=dict)
    decision: dict[str, Any] | None = None

    @property
    def channel_names(self) -> list[str]:
        return [c.name for c in self.channels]


def _check_keys(table: Any, allowed: dict, where: str) -> None:
    if not isinstance(table, dict):
        raise DataError(f"config: [{where}] must be a table, got {type(table).__name__}")
    for k, v in table.items():
        if k not in allowed:
            raise DataError(f"config: unknown key {k!r} in [{where}]; allowed: {sorted(allowed)}")
        want = allowed[k]
        if not isinstance(v, want) or (isinstance(v, bool) and want is not bool):
            names = want.__name__ if isinstance(want, type) else " or ".join(t.__name__ for t in want)
            raise DataError(f"config: [{where}].{k} must be {names}, got {type(v).__name__} {v!r}")


def load_config(path: str | Path) -> MonitorConfig:
    """Read and validate a monitor configuration file (TOML).

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "m.toml"
    >>> _ = p.write_text('[channels.y]\\nscale = 2.0\\n[[generators]]\\nartifact = "obs"\\n')
    >>> cfg = load_config(p)
    >>> cfg.channel_names, cfg.channels[0].scale, cfg.generators
    (['y'], 2.0, ['obs'])
    """
    path = Path(path)
    try:
        raw = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise DataError(f"{path}: no such config file") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise DataError(f"{path}: not valid TOML ({exc})") from None
    for k in raw:
        if k not in _TOP:
            raise DataError(f"config: unknown section [{k}]; sections are {sorted(_TOP)}")
    for sec, allowed in _SCHEMA.items():
        if sec in raw:
            _check_keys(raw[sec], allowed, sec)
    mon = raw.get("monitor", {})
    on_invalid = mon.get("on_invalid", "hold")
    if on_invalid not in ("hold", "raise"):
        raise DataError(f"config: [monitor].on_invalid must be 'hold' or 'raise', got {on_invalid!r}")
    chans = []
    ch_tab = raw.get("channels", {})
    if not isinstance(ch_tab, dict) or not ch_tab:
        raise DataError("config: [channels] must name at least one channel ([channels.NAME] tables)")
    for name, spec in ch_tab.items():
        _check_keys(spec, _CHANNEL_KEYS, f"channels.{name}")
        c = ChannelMap(name, spec.get("source", name), float(spec.get("scale", 1.0)),
                       float(spec.get("offset", 0.0)), spec.get("unit", ""))
        if not (np.isfinite(c.scale) and np.isfinite(c.offset)) or c.scale == 0:
            raise DataError(f"config: [channels.{name}] scale must be finite and non-zero and offset finite")
        chans.append(c)
    stages = {}
    for sec in ("generators", "processors"):
        items = raw.get(sec, [])
        if not isinstance(items, list):
            raise DataError(f"config: {sec} must be an array of tables ([[{sec}]])")
        for i, it in enumerate(items):
            _check_keys(it, _STAGE_KEYS, f"{sec}[{i}]")
            if "artifact" not in it:
                raise DataError(f"config: [[{sec}]] number {i + 1} needs an 'artifact' name")
        stages[sec] = [it["artifact"] for it in items]
    declarative = "plant" in raw.get("design", {})
    if declarative:
        from .declarative import DESIGN_KEYS, GENERATORS, PROCESSORS, decision_for

        for key in DESIGN_KEYS:
            if key in raw["design"] and not isinstance(raw["design"][key], dict):
                raise DataError(f"config: [design.{key}] must be a table")
        if raw["design"].get("recipe"):
            raise DataError("config: [design] declares a plant and a recipe; give one of them")
        if not stages["generators"] and not stages["processors"]:
            stages["generators"], stages["processors"] = list(GENERATORS), list(PROCESSORS)
    if not stages["generators"]:
        raise DataError("config: at least one [[generators]] entry is needed (or a declarative "
                        "[design.plant], which makes them)")
    dec = raw.get("decision")
    if dec is None and declarative:
        dec = decision_for(raw["design"])
    if dec is not None and "channels" not in dec:
        raise DataError("config: [decision] needs 'channels'")
    log = dict(raw.get("log", {}))
    if log.get("format", "auto") not in ("auto", "csv", "can"):
        raise DataError(f"config: [log].format must be 'auto', 'csv' or 'can', got {log['format']!r}")
    return MonitorConfig(path=path, name=mon.get("name", path.stem),
                         artifacts=(path.parent / mon.get("artifacts", "designs")).resolve(),
                         on_invalid=on_invalid, channels=chans, generators=stages["generators"],
                         processors=stages["processors"], log=log, design=dict(raw.get("design", {})),
                         decision=dec)


def _import_recipe(cfg: MonitorConfig, recipe: str):
    """The recipe function ``module:function``. A module (or package) beside the config file is
    found there first, without PYTHONPATH: ``recipe = "my_recipe:design"`` next to
    ``my_recipe.py``. Recipes written for an older fdikit layout are mapped (:func:`moved`)."""
    from .declarative import import_object

    func = import_object(moved(recipe), cfg.path.parent, where=f"{cfg.path}: design recipe {recipe!r}")
    if not callable(func):
        raise DataError(f"{cfg.path}: design recipe {recipe!r} is not a function")
    return func


def run_design(cfg: MonitorConfig) -> dict[str, Path]:
    """Run the config's design recipe and save every design it returns as an artifact."""
    recipe = cfg.design.get("recipe")
    report = None
    if not recipe and "plant" in cfg.design:
        from .declarative import design_monitor

        designs = design_monitor(cfg.design, cfg.path.parent)
        report = designs.pop("_report")
    else:
        if not recipe:
            raise DataError(f"{cfg.path}: [design].recipe is not set (e.g. 'package.module:function'), "
                            "and there is no declarative [design.plant]")
        func = _import_recipe(cfg, recipe)
        designs = func(dict(cfg.design.get("params", {})))
    if not isinstance(designs, dict) or not designs:
        raise DataError(f"design recipe {recipe!r} must return a non-empty dict name -> design")
    cfg.artifacts.mkdir(parents=True, exist_ok=True)
    units = {c.name: c.unit for c in cfg.channels if c.unit}
    out = {name: save_artifact(cfg.artifacts / name, obj, units=units, meta={"config": cfg.name})
           for name, obj in designs.items()}
    if report is not None:
        import json

        from ..base.state import _atomic_write

        path = cfg.artifacts / "design_report.json"
        text = json.dumps(report, indent=1, default=str)
        _atomic_write(path, lambda fh: fh.write(text.encode()))
        out["design_report"] = path
    return out


def _runtime(obj: Any) -> Any:
    kind = type(obj).__name__
    if kind in RUNTIMES:
        mod, _, cls = RUNTIMES[kind].partition(":")
        return getattr(importlib.import_module(mod), cls)(obj)
    return obj


def build_monitor(cfg: MonitorConfig) -> Monitor:
    """Load the artifacts named by the config and chain them into a :class:`Monitor`."""
    gens = [_runtime(load_artifact(cfg.artifacts / a)) for a in cfg.generators]
    procs = [_runtime(load_artifact(cfg.artifacts / a)) for a in cfg.processors]
    for a, g in zip(cfg.generators, gens):
        missing = [n for n in (*g.u_names, *g.y_names) if n not in cfg.channel_names]
        if missing:
            raise DataError(f"artifact {a!r} reads channels {missing} that the config does not define; "
                            f"config channels: {cfg.channel_names}")
    decision = None
    if cfg.decision is not None:
        decision = Decision(list(cfg.decision["channels"]), float(cfg.decision.get("level", 0.5)),
                            dict(cfg.decision.get("names", {})))
    return Monitor(gens, procs, decision, on_invalid=cfg.on_invalid)


def read_log(cfg: MonitorConfig, path: str | Path) -> Signals:
    """Read a recorded log as the config's ``[log]`` table says (the source channels only).

    A ``.csv`` file (or ``format = "csv"``) is a table of signals with the time column
    ``[log].time``; anything else goes to :func:`fdikit.io.read_log` (BLF, ASC, candump, MDF4,
    Parquet), with ``[log].dbc`` for raw CAN frames.
    """
    from .. import io

    path = Path(path)
    fmt = cfg.log.get("format", "auto")
    sources = list(dict.fromkeys(c.source for c in cfg.channels))
    if fmt == "csv" or (fmt == "auto" and path.suffix.lower() == ".csv"):
        return io.read_csv(path, time=cfg.log.get("time", "t"), columns=sources, rate=cfg.log.get("rate"))
    dbc = cfg.log.get("dbc")
    if fmt == "can" and not dbc:
        raise DataError(f"{cfg.path}: a CAN log needs [log].dbc")
    return io.read_log(path, cfg.path.parent / dbc if dbc else None, sources, cfg.log.get("rate"))


def map_channels(cfg: MonitorConfig, log: Signals) -> Signals:
    """Monitor channels from log channels: ``scale * source - offset``, renamed; NaN (gaps) kept."""
    idx = log.index([c.source for c in cfg.channels])
    scale = np.array([c.scale for c in cfg.channels])
    offset = np.array([c.offset for c in cfg.channels])
    v = log.values[:, :, idx] * scale - offset
    return Signals(log.t, v, cfg.channel_names, [c.unit for c in cfg.channels], check=False)


def map_sample(cfg: MonitorConfig, row: dict[str, float]) -> dict[str, float]:
    """One sample (source name -> value) mapped to monitor channels (for follow mode)."""
    out = {}
    for c in cfg.channels:
        if c.source not in row:
            raise DataError(f"sample lacks source channel {c.source!r} for {c.name!r}; it has {sorted(row)}")
        out[c.name] = c.scale * float(row[c.source]) - c.offset
    return out
