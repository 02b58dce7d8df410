"""Config-driven monitors: a TOML file names the channels, the design artifacts, the processors and
the decision; designs are data produced once (``fdikit design``) and loaded by the runtime
(``fdikit monitor``) without changing code.

Schema (every key is checked: an unknown key or a wrong type is an error naming it)::

    [monitor]
    name = "two-mass"             # free text
    artifacts = "designs"         # directory of the design artifacts, relative to this file
    on_invalid = "hold"           # "hold" (flag bad samples, keep state) or "raise"
    max_gap = 0.05                # s: a longer time step is a gap (state held, "cannot judge",
                                  #    warm-up after it); see fdikit.monitor.Monitor
    warmup = 1.0                  # s: warm-up at the start and after a gap (nothing announced)
    max_abs = 1e12                # a value of larger magnitude is invalid (a 1e300 spike)

    [log]                         # how `fdikit monitor LOG` reads a recorded log
    format = "auto"               # "auto" (by extension), "csv", "can" (BLF, ASC or candump, by
                                  # content) or a reader's name ("candump", "parquet", "mdf", ...)
    time = "t"                    # time column of a table log (CSV, Parquet, topic folder)
    dbc = "car.dbc"               # CAN logs: the DBC, relative to this file
    rate = 100.0                  # Hz: resample onto this grid (CAN logs need it)
    time_unit = "auto"            # unit of the time column: "auto", "s", "ms", "us" or "ns";
                                  # absolute (epoch) timestamps start at 0, at full precision
                                  # (fdikit.io.timebase), in batch and follow mode alike

    [channels.pos1]               # a monitor channel (the name the designs use)
    source = "POS.P1"             # the column / "MESSAGE.SIGNAL" in the log (default: the name)
    scale = 1.0                   # value = scale * source - offset
    offset = 0.0                  # nominal operating point to subtract (ng-chen-speyer, Section V);
                                  # "identified": the mean of the nominal logs that identified the
                                  # plant ([design.plant].identify; the design report's offsets)
    unit = "m"                    # unit after scaling (documentation, stored in artifacts)
    min = -1.0                    # plausibility, in the channel's monitor units (after scale and
    max = 1.0                     #   offset): physical range,
    max_rate = 10.0               #   largest rate of change (unit/s),
    spike = 8.0                   #   spike: an increment more than this many robust standard
    spike_window = 50             #   deviations (1.4826 MAD) of the recent increments (samples);
                                  #   a sample that fails is invalid, flagged with its reason and
                                  #   never fed to a filter (fdikit.monitor.Plausibility)
    # shared_source = true        # allow another channel to read the same source column

    [design]                      # how `fdikit design CONFIG` makes the artifacts
    recipe = "package.module:function"   # function(params: dict) -> {artifact name: design}
    [design.params]               # passed to the recipe as a dict
    dt = 0.01

    [[generators]]                # residual generators, in order
    artifact = "observer"         # <artifacts>/observer.json (+ .npz)

    [[processors]]                # residual processors, in order
    artifact = "hold"

    [decision]                    # announcements: one per fault episode (onset and cleared)
    channels = ["r:pos2:alarm"]
    level = 0.5
    names = { "r:pos2:alarm" = "sensor:pos2" }
    clear_level = 0.25            # the episode clears below this level ...
    clear_after = 0.5             # ... held this long (see fdikit.monitor.Decision)
    sizes = { "r:pos2:alarm" = "r:pos2" }   # channel whose value is the episode's size estimate
    # groups = { pos2 = ["sensor:pos2:bias", "sensor:pos2:gain"] }   # alternatives of one component:
    #                             # one episode, a revision announced as a "change" event
    # confirm_after = 2.0         # s a group's own (unspecific) name waits for its group's or
    #                             # another group's specific names to confirm or contradict it
    # processor = "diagnosis"     # instead of channels: announce what this processor artifact
    #                             # decides (its `announce` and `size_channels`, e.g. a
    #                             # fdikit.isolate.DMatrixDecision: one diagnosis per episode)

Two channels reading one source column are refused (two monitor channels that always agree
look to the residuals like a fault), unless each of them sets ``shared_source = true``.

``fdikit design`` stamps every artifact with :func:`design_hash` (a hash of the ``[design]``
section and the files it names); :func:`build_monitor` refuses artifacts whose stamp differs from
the config's (a design changed since ``fdikit design``: rerun it). Artifacts without a stamp
(written by an older fdikit) are accepted as they are.
"""

from __future__ import annotations

import hashlib
import importlib
import inspect
import json
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..base.artifacts import load_artifact, moved, read_manifest, save_artifact
from ..base.paths import config_path
from ..errors import DataError
from ..signals import Signals
from .core import Decision, Monitor
from .logs import check_log_table

__all__ = ["TIME_UNITS", "ChannelMap", "MonitorConfig", "build_monitor", "design_hash", "identified_offsets",
           "load_config", "map_channels", "nominal_log_paths", "nominal_logs", "read_log", "run_design",
           "source_plausibility"]

#: ``[log].time_unit`` -> seconds per unit (``"auto"``: by the magnitude of the first timestamp,
#: see :mod:`fdikit.io.timebase`).
TIME_UNITS: dict[str, float | None] = {"auto": None, "s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}

#: Designs that need a runtime wrapper: artifact kind -> "module:class".
RUNTIMES = {
    "ObserverDesign": "fdikit.residuals.observer:ObserverResidual",
    "FilterDesign": "fdikit.residuals.fdf:FaultDetectionFilter",
}

_SCHEMA: dict[str, dict[str, type | tuple[type, ...]]] = {
    "monitor": {"name": str, "artifacts": str, "on_invalid": str, "max_gap": (int, float),
                "warmup": (int, float), "max_abs": (int, float)},
    "log": {"format": str, "time": str, "dbc": str, "rate": (int, float), "time_unit": str, "resample": str},
    "design": {"recipe": str, "params": dict, "sample_time": (int, float), "plant": dict, "faults": dict,
               "disturbances": dict, "noise": dict, "alarm": dict, "structure": dict,
               "nominal_log": (str, list), "accept_miscalibrated": bool, "detect": dict},
    "decision": {"channels": list, "level": (int, float), "names": dict, "clear_level": (int, float),
                 "clear_after": (int, float), "sizes": dict, "processor": str, "groups": dict,
                 "confirm_after": (int, float), "unconfirmed": str},
}
#: Plausibility keys of a channel (monitor units), passed to :class:`fdikit.monitor.Plausibility`.
PLAUSIBILITY_KEYS = ("min", "max", "max_rate", "spike")
_CHANNEL_KEYS: dict[str, type | tuple[type, ...]] = {"source": str, "scale": (int, float),
                                                      "offset": (int, float, str), "unit": str,
                                                      **{k: (int, float) for k in PLAUSIBILITY_KEYS},
                                                      "spike_window": int, "shared_source": bool}
_STAGE_KEYS: dict[str, type | tuple[type, ...]] = {"artifact": str}
_TOP = {"monitor", "log", "channels", "design", "generators", "processors", "decision"}


@dataclass
class ChannelMap:
    """One monitor channel: ``value = scale * log[source] - offset``.

    ``plausibility`` holds the channel's checks (``min``, ``max``, ``max_rate``, ``spike``, in the
    monitor units); ``shared_source`` allows another channel to read the same source.
    """

    name: str
    source: str
    scale: float = 1.0
    offset: float = 0.0
    unit: str = ""
    plausibility: dict[str, float] = field(default_factory=dict)
    shared_source: bool = False
    #: ``offset = "identified"``: the offset is the identification's operating point, read from the
    #: design report by :func:`identified_offsets` (NaN until then)
    offset_identified: bool = False


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
    #: ``[monitor]`` runtime options (``max_gap``, ``warmup``, ``max_abs``) that are set
    runtime: dict[str, float] = field(default_factory=dict)

    @property
    def channel_names(self) -> list[str]:
        return [c.name for c in self.channels]

    @property
    def time_unit(self) -> str:
        """Unit of the log's time column (``[log].time_unit``, default ``"auto"``)."""
        return str(self.log.get("time_unit", "auto"))


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
        raw = tomllib.loads(path.read_text(encoding="utf-8-sig"))   # a BOM (Windows editors) is not TOML
    except FileNotFoundError:
        raise DataError(f"{path}: no such config file") from None
    except IsADirectoryError:
        raise DataError(f"{path}: is a folder, not a config file (TOML)") from None
    except OSError as exc:
        raise DataError(f"{path}: cannot read the config file ({exc.strerror or exc})") from None
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
        plaus: dict[str, Any] = {k: float(spec[k]) for k in PLAUSIBILITY_KEYS if k in spec}
        if "spike_window" in spec:
            if "spike" not in spec:
                raise DataError(f"config: [channels.{name}].spike_window needs spike (the threshold)")
            if spec["spike_window"] < 5:
                raise DataError(f"config: [channels.{name}].spike_window must be >= 5 samples, got "
                                f"{spec['spike_window']}")
            plaus["window"] = int(spec["spike_window"])
        off = spec.get("offset", 0.0)
        ident = isinstance(off, str)
        if ident and off != "identified":
            raise DataError(f"config: [channels.{name}].offset must be a number or \"identified\", "
                            f"got {off!r}")
        c = ChannelMap(name, spec.get("source", name), float(spec.get("scale", 1.0)),
                       math.nan if ident else float(off), spec.get("unit", ""), plaus,
                       bool(spec.get("shared_source", False)), ident)
        if not (np.isfinite(c.scale) and (ident or np.isfinite(c.offset))) or c.scale == 0:
            raise DataError(f"config: [channels.{name}] scale must be finite and non-zero and offset finite")
        _check_plausibility(plaus, f"channels.{name}", c.unit)
        chans.append(c)
    by_source: dict[str, list[ChannelMap]] = {}
    for c in chans:
        by_source.setdefault(c.source, []).append(c)
    for src, users in by_source.items():
        if len(users) > 1 and not all(c.shared_source for c in users):
            names = [c.name for c in users]
            raise DataError(f"config: channels {names} all read the source column {src!r}: two monitor "
                            "channels that always agree look like a fault to the residuals (a copy-paste "
                            "slip?). Map each channel to its own source, or set shared_source = true in "
                            f"each of [channels.{names[0]}] ... [channels.{names[-1]}] if this is meant")
    runtime = {}
    for key in ("max_gap", "warmup", "max_abs"):
        if key in mon:
            v = float(mon[key])
            ok = np.isfinite(v) and (v >= 0 if key == "warmup" else v > 0)
            if not ok:
                raise DataError(f"config: [monitor].{key} must be a finite number "
                                f"{'>= 0' if key == 'warmup' else '> 0'}, got {mon[key]!r}")
            runtime[key] = v
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
    if "detect" in raw.get("design", {}) and not declarative:
        raise DataError("config: [design.detect] smooths a declarative [design.plant]'s features; a recipe "
                        "makes its own processors")
    identified = [c.name for c in chans if c.offset_identified]
    if identified and not (isinstance(raw.get("design", {}).get("plant"), dict)
                           and "identify" in raw["design"]["plant"]):
        raise DataError(f"config: [channels.{identified[0]}].offset = \"identified\" needs an identified "
                        "plant ([design.plant] identify = {...})")
    if declarative:
        from .declarative import DESIGN_KEYS, GENERATORS, decision_for, processors_for

        for key in DESIGN_KEYS:
            if key in raw["design"] and not isinstance(raw["design"][key], dict):
                raise DataError(f"config: [design.{key}] must be a table")
        if raw["design"].get("recipe"):
            raise DataError("config: [design] declares a plant and a recipe; give one of them")
        if not stages["generators"] and not stages["processors"]:
            stages["generators"], stages["processors"] = list(GENERATORS), processors_for(raw["design"])
    if not stages["generators"]:
        raise DataError("config: at least one [[generators]] entry is needed (or a declarative "
                        "[design.plant], which makes them)")
    dec = raw.get("decision")
    if dec is None and declarative:
        dec = decision_for(raw["design"])
    if dec is not None and "processor" in dec:
        if "channels" in dec:
            raise DataError("config: [decision] takes 'channels' or 'processor', not both")
        if dec["processor"] not in stages["processors"]:
            raise DataError(f"config: [decision].processor = {dec['processor']!r} is not one of the "
                            f"[[processors]] artifacts {stages['processors']}")
        for key in ("names", "sizes"):
            if key in dec:
                raise DataError(f"config: [decision].{key} comes from the processor with "
                                f"[decision].processor; remove it")
    elif dec is not None and "channels" not in dec:
        raise DataError("config: [decision] needs 'channels' (or 'processor')")
    if dec is not None and "channels" in dec:
        _check_decision(dec)
    log = dict(raw.get("log", {}))
    check_log_table(log)
    if "rate" in log and not (np.isfinite(log["rate"]) and log["rate"] > 0):
        raise DataError(f"config: [log].rate must be a positive, finite number of samples per second (Hz), "
                        f"got {log['rate']!r}")
    if log.get("resample", "previous") not in ("previous", "linear"):
        raise DataError(f"config: [log].resample must be 'previous' (the causal hold of each signal's "
                        f"last sample, the default) or 'linear' (interpolation with the next sample: "
                        f"not causal), got {log['resample']!r}")
    if log.get("time_unit", "auto") not in TIME_UNITS:
        raise DataError(f"config: [log].time_unit must be one of {list(TIME_UNITS)}, got "
                        f"{log['time_unit']!r}")
    artifacts = config_path(path.parent, mon.get("artifacts", "designs"),
                            where=f"{path}: [monitor].artifacts")
    if artifacts.exists() and not artifacts.is_dir():
        raise DataError(f"{path}: [monitor].artifacts = {mon.get('artifacts', 'designs')!r} is a file "
                        f"({str(artifacts)!r}); the design artifacts need a folder: name a folder (it is "
                        "created by fdikit design) or move the file away")
    return MonitorConfig(path=path, name=mon.get("name", path.stem), artifacts=artifacts,
                         on_invalid=on_invalid, channels=chans, generators=stages["generators"],
                         processors=stages["processors"], log=log, design=dict(raw.get("design", {})),
                         decision=dec, runtime=runtime)


def _check_plausibility(p: dict[str, float], where: str, unit: str) -> None:
    """Refuse plausibility limits that cannot be meant (naming the key and its value)."""
    u = f" {unit}" if unit else ""
    for k, v in p.items():
        if not np.isfinite(v):
            raise DataError(f"config: [{where}].{k} must be finite, got {v}")
    if "min" in p and "max" in p and not p["min"] < p["max"]:
        raise DataError(f"config: [{where}] min = {p['min']}{u} must be below max = {p['max']}{u}")
    for k, what in (("max_rate", f"{unit or 'unit'}/s"), ("spike", "robust standard deviations")):
        if k in p and not p[k] > 0:
            raise DataError(f"config: [{where}].{k} must be > 0 ({what}), got {p[k]}")


def _check_decision(dec: dict) -> None:
    """Types and cross-references of ``[decision]`` (an implied declarative one included)."""
    chans = dec["channels"]
    if not all(isinstance(c, str) for c in chans):
        raise DataError(f"config: [decision].channels must be a list of channel names, got {chans!r}")
    for key in ("names", "sizes"):
        tab = dec.get(key, {})
        for ch, v in tab.items():
            if ch not in chans:
                raise DataError(f"config: [decision].{key} names channel {ch!r}, which is not in "
                                f"[decision].channels {chans}")
            if not isinstance(v, str):
                raise DataError(f"config: [decision].{key}.{ch} must be a name, got {v!r}")
    for g, members in dec.get("groups", {}).items():
        if not (isinstance(members, list) and all(isinstance(m, str) for m in members)):
            raise DataError(f"config: [decision].groups.{g} must be a list of announced names, got "
                            f"{members!r}")
    level = float(dec.get("level", 0.5))
    if not (np.isfinite(level) and 0 < level <= 1):
        raise DataError(f"config: [decision].level must be in (0, 1] (the alarm and probability channels "
                        f"it compares are in [0, 1]), got {dec.get('level')!r}")
    if "clear_level" in dec:
        cl = float(dec["clear_level"])
        if not (np.isfinite(cl) and cl <= level):
            raise DataError(f"config: [decision].clear_level = {cl} must be finite and not above "
                            f"level = {level} (an episode clears below clear_level)")
    if "clear_after" in dec:
        ca = float(dec["clear_after"])
        if not (np.isfinite(ca) and ca >= 0):
            raise DataError(f"config: [decision].clear_after must be a finite number >= 0, got {ca}")


def design_hash(cfg: MonitorConfig) -> str:
    """The hash stamped on every artifact by :func:`run_design`: SHA-256 of the ``[design]``
    section (recipe, parameters, declarative tables; canonical JSON) and of the contents of the
    files it names (``[design.plant].file``, ``[design.noise].nominal_log``, every log of
    ``[design.plant].identify.logs``; a folder log by the contents of its files). A design read
    from logs also hashes the ``[log]`` table that says how they are read (format, time column,
    time unit, rate, and the DBC's contents).

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "m.toml"
    >>> _ = p.write_text('[channels.r]\\n[design]\\nrecipe = "m:f"\\n[design.params]\\nZ = 3\\n'
    ...                  '[[generators]]\\nartifact = "g"\\n')
    >>> h = design_hash(load_config(p))
    >>> _ = p.write_text(p.read_text().replace("Z = 3", "Z = 4"))
    >>> design_hash(load_config(p)) == h
    False
    """
    text = json.dumps(cfg.design, sort_keys=True, default=str, separators=(",", ":"))
    h = hashlib.sha256(text.encode())
    if cfg.design.get("nominal_log"):
        try:
            nominal = nominal_log_paths(cfg)
        except DataError:
            nominal = []
        for f in nominal:
            h.update(f"\0nominal_log\0{f.name}\0".encode())
            h.update(hashlib.sha256(f.read_bytes()).digest())
    refs: list[tuple[str, Any]] = []
    for sec, key in (("plant", "file"), ("noise", "nominal_log")):
        tab = cfg.design.get(sec)
        if isinstance(tab, dict) and isinstance(tab.get(key), str):
            refs.append((f"{sec}.{key}", tab[key]))
    plant = cfg.design.get("plant")
    ident = plant.get("identify") if isinstance(plant, dict) else None
    logs = ident.get("logs") if isinstance(ident, dict) else None
    for k, f in enumerate([logs] if isinstance(logs, str) else logs if isinstance(logs, list) else []):
        if isinstance(f, str):
            refs.append((f"plant.identify.logs[{k}]", f))
    if any(r[0] != "plant.file" for r in refs):   # logs are read as [log] says
        keys = ("format", "time", "time_unit", "rate", "dbc", "resample")
        log = {k: cfg.log[k] for k in keys if k in cfg.log}
        if log:
            h.update(b"\0[log]\0" + json.dumps(log, sort_keys=True, separators=(",", ":")).encode())
        if isinstance(log.get("dbc"), str):
            refs.append(("log.dbc", log["dbc"]))
    for name, ref in refs:
        try:
            f = config_path(cfg.path.parent, ref, where=f"[design.{name}]")
        except DataError:
            f = cfg.path.parent / ref
        h.update(f"\0{name}\0".encode())
        h.update(_file_digest(f))
    return h.hexdigest()


def _file_digest(f: Path) -> bytes:
    """SHA-256 of a file's contents; a folder: of its files' relative names and contents, sorted."""
    try:
        if f.is_dir():
            d = hashlib.sha256()
            for g in sorted(x for x in f.rglob("*") if x.is_file()):
                name = g.relative_to(f).as_posix().encode()
                d.update(name + b"\0" + hashlib.sha256(g.read_bytes()).digest())
            return d.digest()
        return hashlib.sha256(f.read_bytes()).digest()
    except OSError:
        return b"missing"


def _import_recipe(cfg: MonitorConfig, recipe: str):
    """The recipe function ``module:function``. A module (or package) beside the config file is
    found there first, without PYTHONPATH: ``recipe = "my_recipe:design"`` next to
    ``my_recipe.py``. Recipes written for an older fdikit layout are mapped (:func:`moved`)."""
    from .declarative import import_object

    func = import_object(moved(recipe), cfg.path.parent, where=f"{cfg.path}: design recipe {recipe!r}")
    if not callable(func):
        raise DataError(f"{cfg.path}: design recipe {recipe!r} is not a function")
    return func


def nominal_log_paths(cfg: MonitorConfig) -> list[Path]:
    """The files of ``[design].nominal_log`` (a path or a list; globs; relative to the config),
    sorted per entry.

    Raises
    ------
    DataError
        An entry that matches no file (naming it and the folder looked in).
    """
    import glob

    spec = cfg.design.get("nominal_log")
    entries = [spec] if isinstance(spec, str) else list(spec or [])
    out: list[Path] = []
    for k, e in enumerate(entries):
        if not isinstance(e, str):
            raise DataError(f"{cfg.path}: [design].nominal_log[{k}] must be a path, got {e!r}")
        p = config_path(cfg.path.parent, e, where=f"{cfg.path}: [design].nominal_log[{k}]")
        hits = sorted(Path(h) for h in glob.glob(str(p))) if glob.has_magic(str(p)) else \
            ([p] if p.exists() else [])
        if not hits:
            raise DataError(f"{cfg.path}: [design].nominal_log[{k}] = {e!r} matches no file (looked for "
                            f"{p})")
        out.extend(hits)
    return out


def nominal_logs(cfg: MonitorConfig) -> dict[str, Signals]:
    """The ``[design].nominal_log`` logs, read as ``[log]`` says and mapped to monitor channels:
    ``{path: Signals}``."""
    return {str(p): map_channels(cfg, read_log(cfg, p)) for p in nominal_log_paths(cfg)}


def run_design(cfg: MonitorConfig) -> dict[str, Path]:
    """Run the config's design recipe and save every design it returns as an artifact.

    A declarative design and a recipe that returns a ``"_report"`` entry (a plain dict, e.g. with
    ``claims``: the false-alarm rates the design states) also write ``design_report.json``.
    """
    recipe = cfg.design.get("recipe")
    report = None
    if not recipe and "plant" in cfg.design:
        from .declarative import design_monitor

        nominal = nominal_logs(cfg) if cfg.design.get("nominal_log") else None
        designs = design_monitor(cfg.design, cfg.path.parent, log=cfg.log, nominal=nominal)
        report = designs.pop("_report")
    else:
        if not recipe:
            raise DataError(f"{cfg.path}: [design].recipe is not set (e.g. 'package.module:function'), "
                            "and there is no declarative [design.plant]")
        if cfg.design.get("nominal_log"):
            raise DataError(f"{cfg.path}: [design].nominal_log sets the thresholds of a declarative "
                            "[design.plant]; a recipe reads its own data ([design.params])")
        func = _import_recipe(cfg, recipe)
        designs = func(dict(cfg.design.get("params", {})))
        if isinstance(designs, dict) and isinstance(designs.get("_report"), dict):
            designs = dict(designs)
            report = designs.pop("_report")
    if not isinstance(designs, dict) or not designs:
        raise DataError(f"design recipe {recipe!r} must return a non-empty dict name -> design")
    cfg.artifacts.mkdir(parents=True, exist_ok=True)
    units = {c.name: c.unit for c in cfg.channels if c.unit}
    meta = {"config": cfg.name, "design_hash": design_hash(cfg)}
    out = {name: save_artifact(cfg.artifacts / name, obj, units=units, meta=meta)
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


def _check_fresh(cfg: MonitorConfig, names: list[str]) -> None:
    """Refuse artifacts designed from another ``[design]`` section than the config's."""
    if not cfg.design:
        return
    want = None
    missing = [a for a in names if not (cfg.artifacts / f"{a}.json").exists()]
    if missing:
        raise DataError(f"{cfg.path}: the config names artifacts {missing} that {cfg.artifacts} does not "
                        f"hold (the config changed since 'fdikit design', or it was never run). Run "
                        f"'fdikit design {cfg.path}' to build them")
    for a in names:
        stamp = read_manifest(cfg.artifacts / a).get("meta", {}).get("design_hash")
        if stamp is None:
            continue  # written by an fdikit that did not stamp designs: accepted as it is
        want = want or design_hash(cfg)
        if stamp != want:
            raise DataError(f"{cfg.path}: the artifact {a!r} ({cfg.artifacts / a}.json) was designed from "
                            f"another [design] section (design_hash {stamp[:12]}..., the config's is "
                            f"{want[:12]}...): the design changed since 'fdikit design'. Rerun "
                            f"'fdikit design {cfg.path}' to rebuild the artifacts")


def _supported(func, keys: list[str], what: str) -> None:
    if not keys:  # nothing to check (a fleet reads thousands of logs: no signature per log)
        return
    params = inspect.signature(func).parameters
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values()):
        return
    missing = [k for k in keys if k not in params]
    if missing:
        raise DataError(f"this fdikit's {what} does not take {missing} yet; remove them from the config")


def build_monitor(cfg: MonitorConfig) -> Monitor:
    """Load the artifacts named by the config and chain them into a :class:`Monitor`.

    The channels' plausibility checks, the ``[monitor]`` runtime options (gaps, warm-up,
    ``max_abs``) and the ``[decision]`` episode options go to :class:`Monitor` and
    :class:`Decision`.

    Raises
    ------
    DataError
        A missing or inconsistent artifact, a stale design (see :func:`design_hash`), or an
        artifact reading channels the config does not define.
    """
    _check_fresh(cfg, [*cfg.generators, *cfg.processors])
    identified_offsets(cfg)
    gens = [_runtime(load_artifact(cfg.artifacts / a)) for a in cfg.generators]
    procs = [_runtime(load_artifact(cfg.artifacts / a)) for a in cfg.processors]
    for a, g in zip(cfg.generators, gens):
        missing = [n for n in (*g.u_names, *g.y_names) if n not in cfg.channel_names]
        if missing:
            raise DataError(f"artifact {a!r} reads channels {missing} that the config does not define; "
                            f"config channels: {cfg.channel_names}")
    decision = None
    if cfg.decision is not None:
        dec = dict(cfg.decision)
        if "processor" in dec:
            proc = procs[cfg.processors.index(dec["processor"])]
            announce = getattr(proc, "announce", None)
            if not isinstance(announce, dict) or not announce:
                raise DataError(f"{cfg.path}: [decision].processor = {dec['processor']!r} is a "
                                f"{type(proc).__name__}, which announces nothing (it has no 'announce' "
                                "map of channel -> name)")
            dec["channels"], dec["names"] = list(announce), dict(announce)
            dec["sizes"] = dict(getattr(proc, "size_channels", None) or {})
            dec.setdefault("level", 1e-9)
            _check_decision(dec)
        dkw: dict[str, Any] = {}
        if "clear_level" in dec:
            dkw["clear_level"] = float(dec["clear_level"])
        if "clear_after" in dec:
            dkw["clear_after"] = float(dec["clear_after"])
        if dec.get("sizes"):
            dkw["size_channels"] = dict(dec["sizes"])
            if "size_channels" not in inspect.signature(Decision).parameters and "processor" in dec:
                dkw.pop("size_channels")   # sizes stay in the statistics until Decision reports them
        if dec.get("groups"):
            dkw["groups"] = {str(g): list(m) for g, m in dec["groups"].items()}
        if "confirm_after" in dec:
            dkw["confirm_after"] = float(dec["confirm_after"])
        if "unconfirmed" in dec:
            dkw["unconfirmed"] = str(dec["unconfirmed"])
        _supported(Decision, list(dkw), "Decision")
        try:
            decision = Decision(list(dec["channels"]), float(dec.get("level", 0.5)),
                                dict(dec.get("names", {})), **dkw)
        except DataError as exc:
            raise DataError(f"{cfg.path}: [decision]: {exc}") from None
    kw: dict[str, Any] = dict(cfg.runtime)
    plaus = {c.name: c.plausibility for c in cfg.channels if c.plausibility}
    if plaus:
        try:
            from .plausibility import Plausibility
        except ImportError:
            raise DataError("this fdikit's Monitor has no plausibility checks yet; remove min/max/"
                            "max_rate/spike from the [channels] tables") from None
        kw["plausibility"] = {}
        for n, p in plaus.items():
            try:
                kw["plausibility"][n] = Plausibility(**p)
            except DataError as exc:
                raise DataError(f"{cfg.path}: [channels.{n}]: {exc}") from None
    _supported(Monitor, list(kw), "Monitor")
    return Monitor(gens, procs, decision, on_invalid=cfg.on_invalid, **kw)


def read_log(cfg: MonitorConfig, path: str | Path) -> Signals:
    """Read a recorded log as the config's ``[log]`` table says (the source channels only).

    A ``.csv`` file (or ``format = "csv"``) is a table of signals with the time column
    ``[log].time``; anything else goes to :func:`fdikit.io.read_log` (BLF, ASC, candump, MDF4,
    Parquet, ...), with ``[log].dbc`` for raw CAN frames, ``[log].time`` for every table format and
    the declared ``[log].format`` whatever the file is called (:mod:`fdikit.monitor.logs`). The
    channels' ``min``, ``max`` and ``spike`` rules also go to the CAN frame readers (BLF, ASC,
    candump), converted to the source's unit (:func:`source_plausibility`): a frame that breaks
    them is refused before resampling, where one bad frame could otherwise spread over two grid
    samples that are both in range. A FIFO or pipe is read once, interruptibly, before its format
    is sniffed (:func:`fdikit.base.inputs.spooled`).
    """
    from ..base.inputs import is_stream, spooled

    if is_stream(path):
        with spooled(path) as src:
            return _read_log(cfg, src)
    return _read_log(cfg, path)


def _read_log(cfg: MonitorConfig, path: str | Path) -> Signals:
    from .. import io
    from .logs import FRAME_FORMATS, read_options

    sources = list(dict.fromkeys(c.source for c in cfg.channels))
    fmt, kw = read_options(cfg.log, path, cfg.path.parent, signals=sources, where=str(cfg.path))
    if fmt == "recording":
        _supported(io.read_csv, [k for k in kw if k == "time_unit"], "CSV reader (fdikit.io.read_csv)")
        return io.read_csv(path, **kw)
    if fmt in FRAME_FORMATS:
        rules = source_plausibility(cfg)
        if rules:
            kw["plausibility"] = rules
    _supported(io.read_log, [k for k in kw if k == "time_unit"], "log reader (fdikit.io.read_log)")
    return io.read_log(path, **kw)


def source_plausibility(cfg: MonitorConfig) -> dict[str, dict[str, float]]:
    """The channels' raw-frame plausibility rules in their sources' units: source -> ``min``,
    ``max`` (``(value + offset) / scale``, swapped for a negative scale), ``spike`` and ``window``
    (unit-free); where several channels read one source, the tightest of their rules.

    Examples
    --------
    >>> cfg = MonitorConfig.__new__(MonitorConfig)
    >>> cfg.channels = [ChannelMap("yaw", "K.YAW", 0.5, 1.0, "rad/s",
    ...                            {"min": -2.0, "max": 3.0, "spike": 8.0})]
    >>> source_plausibility(cfg)
    {'K.YAW': {'min': -2.0, 'max': 8.0, 'spike': 8.0}}
    """
    out: dict[str, dict[str, float]] = {}
    for c in cfg.channels:
        p = c.plausibility
        rule: dict[str, float] = {}
        lo = None if p.get("min") is None else (p["min"] + c.offset) / c.scale
        hi = None if p.get("max") is None else (p["max"] + c.offset) / c.scale
        if c.scale < 0:
            lo, hi = hi, lo
        if lo is not None:
            rule["min"] = lo
        if hi is not None:
            rule["max"] = hi
        if p.get("spike") is not None:
            rule["spike"] = float(p["spike"])
            if "window" in p:
                rule["window"] = int(p["window"])
        if not rule:
            continue
        old = out.setdefault(c.source, {})
        for k, v in rule.items():
            if k not in old:
                old[k] = v
            elif k == "min":
                old[k] = max(old[k], v)
            else:       # max, spike (window: the first)
                old[k] = old[k] if k == "window" else min(old[k], v)
    return out


def identified_offsets(cfg: MonitorConfig) -> dict[str, float]:
    """Set the offsets of the channels declared ``offset = "identified"`` to the operating point of
    the plant's identification (the nominal logs' mean, ``u_offset`` and ``y_offset`` in
    ``<artifacts>/design_report.json`` written by ``fdikit design``), and return them by channel.

    Raises
    ------
    DataError
        No design report (``fdikit design`` not run), or a channel that the identification has no
        offset for (naming it and those it has).
    """
    todo = [c for c in cfg.channels if c.offset_identified]
    if not todo:
        return {}
    if all(math.isfinite(c.offset) for c in todo):
        return {c.name: c.offset for c in todo}
    path = cfg.artifacts / "design_report.json"
    try:
        ident = json.loads(path.read_text()).get("identification") or {}
    except FileNotFoundError:
        raise DataError(f"{cfg.path}: channels {[c.name for c in todo]} take offset = \"identified\" from "
                        f"{path}, which does not exist: run 'fdikit design {cfg.path}' first") from None
    except (OSError, ValueError) as exc:
        raise DataError(f"{cfg.path}: cannot read the design report {path} ({exc})") from None
    known = {**ident.get("u_offset", {}), **ident.get("y_offset", {})}
    for c in todo:
        if c.name not in known:
            raise DataError(f"{cfg.path}: [channels.{c.name}].offset = \"identified\", but the "
                            f"identification in {path} has no offset for {c.name!r} (it has {sorted(known)})")
        c.offset = float(known[c.name])
    return {c.name: c.offset for c in todo}


def map_channels(cfg: MonitorConfig, log: Signals) -> Signals:
    """Monitor channels from log channels: ``scale * source - offset``, renamed; NaN (gaps) kept
    (``offset = "identified"`` resolved by :func:`identified_offsets`)."""
    identified_offsets(cfg)
    idx = log.index([c.source for c in cfg.channels])
    scale = np.array([c.scale for c in cfg.channels])
    offset = np.array([c.offset for c in cfg.channels])
    v = log.values[:, :, idx] * scale - offset
    return Signals(log.t, v, cfg.channel_names, [c.unit for c in cfg.channels], check=False)


def map_sample(cfg: MonitorConfig, row: dict[str, float]) -> dict[str, float]:
    """One sample (source name -> value) mapped to monitor channels (for follow mode)."""
    if cfg.channels and any(c.offset_identified and not math.isfinite(c.offset) for c in cfg.channels):
        identified_offsets(cfg)
    out = {}
    for c in cfg.channels:
        if c.source not in row:
            raise DataError(f"sample lacks source channel {c.source!r} for {c.name!r}; it has {sorted(row)}")
        out[c.name] = c.scale * float(row[c.source]) - c.offset
    return out
