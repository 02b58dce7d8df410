"""Your own system from a config file: the plant, its faults, its noise and the false-alarm target
declared in TOML instead of written in a Python recipe.

The ``[design]`` table of a monitor config (:mod:`fdikit.monitor.config`) may declare, instead of
(or beside) a ``recipe``::

    [design]
    sample_time = 0.01                 # s: the monitor's sample time (the log's grid)

    [design.plant]                     # ONE of: matrices inline, a file, or a Python object
    A = [[-2.0, 1.0], [0.0, -5.0]]     # inline state-space matrices (continuous unless dt is given)
    B = [[0.0], [5.0]]
    C = [[1.0, 0.0], [0.0, 1.0]]
    # D = [[0.0], [0.0]]
    # dt = 0.01                        # the matrices are already discrete with this sample time
    # file = "plant.npz"               # arrays A, B, C (and D, dt) in an NPZ file beside the config
    # object = "my_plant:model"        # a python-control StateSpace / TransferFunction, a
    #                                  # LinearFaultModel, a fdikit NonlinearModel, or a function
    #                                  # returning one; "module:attr", the module may sit beside
    #                                  # the config
    # identify = { logs = ["nominal1.csv", "nominal2.csv"], inputs = ["V"],
    #              outputs = ["i_meas", "w_meas"], order = "auto", method = "n4sid" }
    #                                  # (rate = 50.0: grid the logs at 50 Hz; a multi-rate log
    #                                  # (ULog, ROS bag) needs it: by default its grid follows the
    #                                  # fastest topic's median period, jitter included)
    #                                  # no model: identified from nominal logs (many records
    #                                  # pooled; fdikit.estimate.identify), discrete at the logs'
    #                                  # sample time, in deviations from the logs' mean operating
    #                                  # point (set [channels.*].offset to it: the design report's
    #                                  # identification.u_offset / y_offset); the noise defaults to
    #                                  # the identified R and Q
    states = ["i", "w"]
    inputs = ["V"]
    outputs = ["i_meas", "w_meas"]

    [design.plant.operating_point]     # NonlinearModel only: where to linearise
    x = { i = 0.0, w = 10.0 }          # state name -> value
    u = { V = 12.0 }                   # input name -> value

    [design.faults]                    # the faults to detect and isolate, by name
    names = ["actuator:V", "sensor:i_meas", "sensor:w_meas"]

    [design.disturbances]              # unknown inputs to decouple: name -> state-equation column
    load = [0.0, -1.0]

    [design.noise]                     # measurement noise: variances per output (unit^2) ...
    measurement = { i_meas = 1e-4, w_meas = 4e-4 }
    process = 1e-8                     # state noise variance (scalar or one per state)
    # nominal_log = "nominal.csv"      # ... or estimated from a nominal log (see estimate_noise)

    nominal_log = ["nominal/*.csv"]    # real nominal logs (one, many, globs; read as [log] says):
                                       # the thresholds are set on their residuals, time-blocked,
                                       # and every claimed rate is measured on held-out data
    # accept_miscalibrated = true      # keep a design whose held-out rate misses its interval

    [design.detect]                    # optional: the EWMA of every feature before the hold,
    smoothing = "ewma"                 # limits on the nominal logs' fit halves; lambda = "auto":
    lambda = "auto"                    # the strongest smoothing they support (declarative_smoothing)

    [design.alarm]                     # the false-alarm target
    pfa = 1e-3                         # per "hour": expected false alarms (onsets) per hour;
    per = "hour"                       # per "sample" or "run": a probability in (0, 1)
    run_length = 60.0                  # s: the length of a "run" when per = "run"
    hold = 5                           # samples over the threshold before an alarm

:func:`plant_from_config`, :func:`noise_from_config` and :func:`alarm_from_config` turn those tables
into a :class:`~fdikit.model.LinearFaultModel`, noise variances and an :class:`AlarmTarget`; every
key is checked and an error names the key and the file.
"""

from __future__ import annotations

import importlib
import math
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..base.paths import config_path
from ..errors import DataError, ModelError
from ..model import LinearFaultModel, linearize
from ..signals import Signals

__all__ = ["DESIGN_KEYS", "GENERATORS", "PROCESSORS", "AlarmTarget", "alarm_from_config", "decision_for",
           "design_monitor", "estimate_noise", "identification_from_config", "import_object",
           "noise_from_config", "plant_from_config", "processors_for", "sample_time"]

#: Keys of the declarative ``[design]`` sub-tables and their types.
DESIGN_KEYS: dict[str, dict[str, type | tuple[type, ...]]] = {
    "plant": {"A": list, "B": list, "C": list, "D": list, "dt": (int, float), "file": str, "object": str,
              "states": list, "inputs": list, "outputs": list, "operating_point": dict, "params": dict,
              "identify": dict},
    "faults": {"names": list},
    "disturbances": {},
    "noise": {"measurement": (dict, int, float), "process": (list, int, float), "nominal_log": str,
              "time": str},
    "alarm": {"pfa": (int, float), "per": str, "run_length": (int, float), "hold": int},
    "structure": {},
    "detect": {"smoothing": str, "lambda": (int, float, str), "candidates": list},
}


def _check(table: Any, allowed: Mapping[str, Any], where: str) -> dict:
    if not isinstance(table, Mapping):
        raise DataError(f"config: [{where}] must be a table, got {type(table).__name__}")
    for k, v in table.items():
        if allowed and k not in allowed:
            raise DataError(f"config: unknown key {k!r} in [{where}]; allowed: {sorted(allowed)}")
        want = allowed.get(k) if allowed else None
        if want is not None and (not isinstance(v, want) or (isinstance(v, bool) and want is not bool)):
            names = want.__name__ if isinstance(want, type) else " or ".join(t.__name__ for t in want)
            raise DataError(f"config: [{where}].{k} must be {names}, got {type(v).__name__} {v!r}")
    return dict(table)


def import_object(spec: str, base_dir: str | Path | None = None, *, where: str = "config") -> Any:
    """The object named ``"module:attribute"``; a module beside the config (``base_dir``) is found
    there without PYTHONPATH.

    Examples
    --------
    >>> import_object("fdikit.model:LinearFaultModel").__name__
    'LinearFaultModel'
    """
    mod, sep, attr = str(spec).partition(":")
    if not sep or not mod or not attr:
        raise DataError(f"{where}: {spec!r} must be 'module:attribute' (module:function for a recipe)")
    here = None if base_dir is None else Path(base_dir).resolve()
    top = mod.split(".")[0]
    local = here is not None and ((here / f"{top}.py").is_file() or (here / top / "__init__.py").is_file())
    if local:
        cached = sys.modules.get(top)
        if cached is not None and Path(getattr(cached, "__file__", "") or "").resolve().parent not in (
                here, here / top):
            raise DataError(f"{where}: the module {top!r} beside the config has the name of an installed "
                            f"module ({cached.__file__}); rename it")
        sys.path.insert(0, str(here))
    try:
        obj: Any = importlib.import_module(mod)
        for part in attr.split("."):
            obj = getattr(obj, part)
    except (ImportError, AttributeError) as exc:
        also = f" (looked beside the config in {here} too)" if here is not None and not local else ""
        raise DataError(f"{where}: {spec!r} cannot be imported ({exc}){also}") from None
    finally:
        if local and sys.path and sys.path[0] == str(here):
            sys.path.pop(0)
    return obj


def _names(spec: Mapping[str, Any], key: str, n: int | None, where: str) -> list[str] | None:
    v = spec.get(key)
    if v is None:
        return None
    if not all(isinstance(s, str) for s in v):
        raise DataError(f"config: [{where}].{key} must be a list of names, got {v!r}")
    if n is not None and len(v) != n:
        raise DataError(f"config: [{where}].{key} has {len(v)} names for {n} {key}")
    return list(v)


def _matrix(v: Any, what: str, where: str) -> np.ndarray:
    try:
        M = np.atleast_2d(np.asarray(v, dtype=float))
    except (TypeError, ValueError):
        raise DataError(f"config: [{where}].{what} must be a matrix of numbers (a list of rows)") from None
    if M.ndim != 2:
        raise DataError(f"config: [{where}].{what} must be 2-D (a list of rows), got shape {M.shape}")
    if not np.all(np.isfinite(M)):
        i, j = np.argwhere(~np.isfinite(M))[0]
        raise DataError(f"config: [{where}].{what}[{i}][{j}] is not finite")
    return M


def _from_object(obj: Any, spec: Mapping[str, Any], where: str) -> LinearFaultModel:
    if callable(obj) and not isinstance(obj, type) and not hasattr(obj, "A") and not hasattr(obj, "f"):
        obj = obj()
    if isinstance(obj, LinearFaultModel):
        return obj.copy()
    if hasattr(obj, "f") and hasattr(obj, "h") and hasattr(obj, "states"):    # a NonlinearModel
        op = _check(spec.get("operating_point", {}), {"x": dict, "u": dict}, f"{where}.operating_point")
        if "x" not in op:
            raise DataError(f"config: a nonlinear plant needs [{where}.operating_point] "
                            "x = {state = value}")
        try:
            return linearize(obj, op["x"], op.get("u"), spec.get("params"))
        except (ModelError, DataError) as exc:
            raise DataError(f"config: [{where}]: cannot linearise at the operating point ({exc})") from None
    try:
        import control
    except ImportError:  # pragma: no cover - a dependency
        control = None
    if control is not None and isinstance(obj, control.TransferFunction | control.StateSpace):
        ss = control.ss(obj) if isinstance(obj, control.TransferFunction) else obj
        return LinearFaultModel.from_statespace(ss)
    raise DataError(f"config: [{where}].object is a {type(obj).__name__}: expected a LinearFaultModel, a "
                    "NonlinearModel, a python-control StateSpace/TransferFunction, or a function "
                    "returning one")


#: Keys of ``[design.plant].identify`` (:func:`identification_from_config`).
IDENTIFY_KEYS: dict[str, type | tuple[type, ...]] = {
    "logs": (list, str), "inputs": list, "outputs": list, "order": (str, int), "method": str, "time": str,
    "criterion": str, "block_rows": int, "validation": (int, float), "rate": (int, float)}


def identification_from_config(spec: Mapping[str, Any], base_dir: str | Path = ".", *,
                               where: str = "design.plant.identify", log: Mapping[str, Any] | None = None):
    """The :class:`~fdikit.estimate.Identification` of an ``identify = {...}`` table: the logs read
    (paths relative to the config, ``~`` and ``$VARS`` expanded) and pooled as records.

    The logs are read as the config's ``log`` table (``[log]``: format, time column, time unit,
    DBC; :mod:`fdikit.monitor.logs`) says; the table's own ``time`` overrides ``[log].time``.

    Examples
    --------
    >>> identification_from_config({"logs": [], "inputs": [], "outputs": ["y"]})
    Traceback (most recent call last):
    ...
    fdikit.errors.DataError: config: [design.plant.identify].logs must name at least one nominal log
    """
    return _identify_logs(spec, base_dir, where, log)[0]


def _identify_logs(spec: Mapping[str, Any], base_dir: str | Path, where: str,
                   log: Mapping[str, Any] | None = None):
    """The Identification of :func:`identification_from_config` and the logs read (Signals)."""
    from ..estimate import identify

    spec = _check(spec, IDENTIFY_KEYS, where)
    logs = [spec["logs"]] if isinstance(spec.get("logs"), str) else list(spec.get("logs") or [])
    if not logs:
        raise DataError(f"config: [{where}].logs must name at least one nominal log")
    for key in ("inputs", "outputs"):
        if key not in spec:
            raise DataError(f"config: [{where}].{key} = [...] is missing (channel names of the logs)")
        _names(spec, key, None, where)
    order = spec.get("order", "auto")
    if order != "auto" and not (isinstance(order, int) and not isinstance(order, bool) and order >= 1):
        raise DataError(f"config: [{where}].order must be \"auto\" or an integer >= 1, got {order!r}")
    method = spec.get("method", "n4sid")
    if method not in ("n4sid", "arx"):
        raise DataError(f"config: [{where}].method must be \"n4sid\" or \"arx\", got {method!r}")
    rate = spec.get("rate")
    if rate is not None and not (math.isfinite(float(rate)) and float(rate) > 0):
        raise DataError(f"config: [{where}].rate must be a positive number of samples per second (Hz), "
                        f"got {rate!r}")
    records = []
    for k, f in enumerate(logs):
        path = config_path(base_dir, f, where=f"[{where}].logs[{k}]")
        if not Path(path).exists():
            raise DataError(f"config: [{where}].logs[{k}] {str(path)!r} does not exist")
        rec = _read_design_log(path, log, base_dir, [*spec["inputs"], *spec["outputs"]], spec.get("time"),
                               rate=rate)
        missing = [c for c in [*spec["inputs"], *spec["outputs"]] if c not in rec.names]
        if missing:
            raise DataError(f"config: [{where}].logs[{k}] {str(path)!r} has no channels {missing}; its "
                            f"channels: {rec.names}")
        records.append(rec)
    kw = {k: spec[k] for k in ("criterion", "block_rows", "validation") if k in spec}
    try:
        return identify(records, spec["inputs"], spec["outputs"], method=method,
                        order=None if order == "auto" else int(order), name="identified", **kw), records
    except (DataError, ModelError) as exc:
        raise DataError(f"config: [{where}]: identification failed: {exc}") from None


def plant_from_config(design: Mapping[str, Any], base_dir: str | Path = ".", *,
                      where: str = "design", log: Mapping[str, Any] | None = None) -> LinearFaultModel:
    """The plant of a declarative ``[design]`` table, with its faults and disturbances declared.

    Parameters
    ----------
    design : mapping
        The ``[design]`` table (``plant``, ``faults``, ``disturbances``; see the module docstring).
    base_dir : path
        Where relative file names and modules are looked up (the config's folder).
    where : str
        The table's name in messages.
    log : mapping, optional
        The config's ``[log]`` table: how identification logs are read.

    Returns
    -------
    LinearFaultModel
        Continuous or discrete as declared, with ``faults.names`` declared and the disturbances
        as the ``d`` group.

    Examples
    --------
    >>> m = plant_from_config({"plant": {"A": [[-1.0]], "B": [[1.0]], "C": [[1.0]], "inputs": ["u"],
    ...                                  "outputs": ["y"]},
    ...                        "faults": {"names": ["actuator:u", "sensor:y"]}})
    >>> m.fault_names, m.dt is None
    (['actuator:u', 'sensor:y'], True)
    """
    return _plant(design, base_dir, where, log)[0]


def _read_design_log(path, log: Mapping[str, Any] | None, base_dir, signals, time: str | None,
                     rate: float | None = None):
    """A nominal log of the design, read as the config's ``[log]`` table says (every column of a
    table; ``signals`` from a CAN or MDF log), ``time`` overriding ``[log].time`` and ``rate`` (an
    identification's own grid) the reader's."""
    from ..base.inputs import spooled
    from ..io import read_log
    from .logs import read_options

    with spooled(path) as src:   # a FIFO or pipe: read once before its format is sniffed
        _, kw = read_options(log or {}, src, base_dir, signals=signals, time=time,
                             tables_as_recordings=False, where="config")
        if rate is not None:
            kw["rate"] = float(rate)
        return read_log(src, **kw)


def _plant(design: Mapping[str, Any], base_dir: str | Path, where: str, log: Mapping[str, Any] | None = None):
    """The plant of :func:`plant_from_config`, its Identification and the logs identified from
    (None, None unless identified)."""
    if "plant" not in design:
        raise DataError(f"config: [{where}.plant] is missing (state-space matrices, a file, an object or "
                        "identify = {logs = [...], ...})")
    spec = _check(design["plant"], DESIGN_KEYS["plant"], f"{where}.plant")
    base = Path(base_dir)
    given = [k for k in ("A", "file", "object", "identify") if k in spec]
    if len(given) != 1:
        raise DataError(f"config: [{where}.plant] needs exactly one of A/B/C matrices, file, object or "
                        f"identify; got {given or 'none'}")
    ident = records = None
    if "identify" in spec:
        extra = [k for k in spec if k != "identify"]
        if extra:
            raise DataError(f"config: [{where}.plant] names and sample time come from the identification; "
                            f"remove {extra}")
        ident, records = _identify_logs(spec["identify"], base, where=f"{where}.plant.identify", log=log)
        model = ident.model
    elif "object" in spec:
        model = _from_object(import_object(spec["object"], base, where=f"[{where}.plant].object"), spec,
                             f"{where}.plant")
        if any(k in spec for k in ("states", "inputs", "outputs")):
            raise DataError(f"config: [{where}.plant] names come from the object; remove "
                            "states/inputs/outputs")
    else:
        if "file" in spec:
            path = config_path(base, spec["file"], where=f"[{where}.plant].file")
            try:
                with np.load(path, allow_pickle=False) as z:
                    mats = {k: z[k] for k in z.files}
            except FileNotFoundError:
                raise DataError(f"config: [{where}.plant].file {str(path)!r} does not exist") from None
            except (ValueError, OSError) as exc:
                raise DataError(f"config: [{where}.plant].file {str(path)!r} is not an NPZ file "
                                f"({exc})") from None
            missing = [k for k in ("A", "B", "C") if k not in mats]
            if missing:
                raise DataError(f"config: [{where}.plant].file {str(path)!r} lacks the arrays {missing}")
            dt = float(mats["dt"]) if "dt" in mats else spec.get("dt")
        else:
            missing = [k for k in ("B", "C") if k not in spec]
            if missing:
                raise DataError(f"config: [{where}.plant] has A but not {missing}")
            mats = {k: spec[k] for k in ("A", "B", "C", "D") if k in spec}
            dt = spec.get("dt")
        A = _matrix(mats["A"], "A", f"{where}.plant")
        n = A.shape[0]
        B = _matrix(mats["B"], "B", f"{where}.plant")
        C = _matrix(mats["C"], "C", f"{where}.plant")
        D = _matrix(mats["D"], "D", f"{where}.plant") if "D" in mats else None
        if A.shape != (n, n):
            raise DataError(f"config: [{where}.plant].A must be square, got shape {A.shape}")
        if B.shape[0] != n:
            if B.shape[1] == n:
                raise DataError(f"config: [{where}.plant].B has shape {B.shape}: it needs {n} rows (one per "
                                "state); is it transposed?")
            raise DataError(f"config: [{where}.plant].B must have {n} rows, got shape {B.shape}")
        if C.shape[1] != n:
            raise DataError(f"config: [{where}.plant].C must have {n} columns, got shape {C.shape}")
        if D is not None and D.shape != (C.shape[0], B.shape[1]):
            raise DataError(f"config: [{where}.plant].D must have shape {(C.shape[0], B.shape[1])}, "
                            f"got {D.shape}")
        if dt is not None and not (float(dt) > 0 and math.isfinite(float(dt))):
            raise DataError(f"config: [{where}.plant].dt must be a positive sample time, got {dt}")
        try:
            model = LinearFaultModel(A, B, C, D, dt=None if dt is None else float(dt),
                                     states=_names(spec, "states", n, f"{where}.plant"),
                                     inputs=_names(spec, "inputs", B.shape[1], f"{where}.plant"),
                                     outputs=_names(spec, "outputs", C.shape[0], f"{where}.plant"))
        except ModelError as exc:
            raise DataError(f"config: [{where}.plant]: {exc}") from None
    dist = _check(design.get("disturbances", {}), {}, f"{where}.disturbances")
    if dist:
        cols = []
        for name, col in dist.items():
            v = np.asarray(col, dtype=float).ravel()
            if v.size != model.n_states or not np.all(np.isfinite(v)):
                raise DataError(f"config: [{where}.disturbances].{name} must be {model.n_states} finite "
                                f"numbers (a state-equation column for the states {model.states}), "
                                f"got {col!r}")
            cols.append(v)
        Bd = np.column_stack([model.B_of("d"), *cols])
        Dd = np.column_stack([model.D_of("d"), np.zeros((model.n_outputs, len(cols)))])
        names_w = model.input_names("w")
        model = LinearFaultModel(model.A, model.B_of("u"), model.C, model.D_of("u"), dt=model.dt,
                                 states=model.states, inputs=model.input_names("u"), outputs=model.outputs,
                                 Bd=Bd, Dd=Dd, disturbances=[*model.input_names("d"), *dist],
                                 Bw=model.B_of("w") if names_w else None,
                                 Dw=model.D_of("w") if names_w else None,
                                 noises=names_w or None, faults=model.fault_names, name=model.name)
    faults = _check(design.get("faults", {}), DESIGN_KEYS["faults"], f"{where}.faults").get("names", [])
    if not faults:
        eg = [f"actuator:{u}" for u in model.inputs[:1]] + [f"sensor:{y}" for y in model.outputs[:1]]
        raise DataError(f"config: [{where}.faults] names = [...] is missing: which faults should the "
                        f"monitor find? e.g. {eg}")
    try:
        model = model.without_faults().with_faults(*faults)
    except ModelError as exc:
        raise DataError(f"config: [{where}.faults]: {exc}") from None
    return model, ident, records


def estimate_noise(signals: Signals, channels: Sequence[str] | None = None) -> dict[str, float]:
    """Measurement-noise variance of each channel of a nominal record, from its second differences.

    For a smooth signal ``s`` plus white noise ``e`` of variance ``sigma^2``, the second difference
    ``y[k+1] - 2 y[k] + y[k-1]`` is ``e``'s (variance ``6 sigma^2``) plus a signal part of order
    ``dt^2 s''``, negligible at a sampled rate well above the signal's band. A robust scale (1.4826
    times the median absolute deviation) keeps rare spikes and steps out of it:
    ``sigma = 1.4826 MAD(d2) / sqrt(6)``. Samples flagged invalid (NaN) are skipped.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> t = np.arange(20000) * 0.01
    >>> s = Signals(t, np.sin(t)[None, :, None] + rng.normal(0, 0.02, (1, t.size, 1)), ["y"])
    >>> round(estimate_noise(s)["y"] ** 0.5, 3)
    0.02
    """
    chans = list(channels) if channels is not None else list(signals.names)
    out = {}
    for c in chans:
        v = signals.values[:, :, signals.index([c])[0]]
        d2 = v[:, 2:] - 2 * v[:, 1:-1] + v[:, :-2]
        d2 = d2[np.isfinite(d2)]
        if d2.size < 100:
            raise DataError(f"channel {c!r}: {d2.size} valid second differences; need at least 100 "
                            "samples to estimate its noise")
        s = 1.4826 * float(np.median(np.abs(d2 - np.median(d2)))) / math.sqrt(6.0)
        if not s > 0:
            raise DataError(f"channel {c!r}: no measurement noise visible (quantised or constant "
                            "signal); give [design.noise].measurement for it")
        out[c] = s * s
    return out


def noise_from_config(design: Mapping[str, Any], model: LinearFaultModel, base_dir: str | Path = ".", *,
                      where: str = "design", identification: Any = None,
                      log: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """``{"measurement": {output: variance}, "process": (n,) variances}`` of a declarative config.

    Measurement variances are given per output (a number applies to every output) or estimated from
    ``nominal_log`` (:func:`estimate_noise`); the process variance defaults to 1e-8 of the unit
    squared per state (a nearly exact model). For an identified plant (``identification``, an
    :class:`~fdikit.estimate.Identification`) without a ``[design.noise]`` table, the diagonals of
    the identified ``R`` and ``Q``; with ``process`` alone, the identified ``R`` and that process
    variance (a smaller ``Q`` than the identified one makes a slower observer, whose residual keeps
    a slow fault longer).
    """
    spec = _check(design.get("noise", {}), DESIGN_KEYS["noise"], f"{where}.noise")
    if identification is not None and set(spec) <= {"process"}:
        r = np.diag(np.asarray(identification.R, float))
        q = np.diag(np.asarray(identification.Q, float)).copy()
        floor = 1e-12 * max(float(np.max(r)), 1e-300)
        meas_id = {y: max(float(v), floor) for y, v in zip(model.outputs, r)}
        if not spec:
            return {"measurement": meas_id, "process": np.maximum(q, 0.0)}
        spec = {**spec, "measurement": meas_id}     # process given: the identified R, the user's Q
    meas = spec.get("measurement")
    if meas is None and "nominal_log" not in spec:
        raise DataError(f"config: [{where}.noise] needs measurement = {{output = variance}} or nominal_log")
    if meas is not None and "nominal_log" in spec:
        raise DataError(f"config: [{where}.noise]: give measurement or nominal_log, not both")
    if "nominal_log" in spec:
        path = config_path(base_dir, spec["nominal_log"], where=f"[{where}.noise].nominal_log")
        rec = _read_design_log(path, log, base_dir, list(model.outputs), spec.get("time"))
        missing = [y for y in model.outputs if y not in rec.names]
        if missing:
            raise DataError(f"config: [{where}.noise].nominal_log {str(path)!r} has no column for the "
                            f"outputs {missing}; its channels: {rec.names}")
        var = estimate_noise(rec, model.outputs)
    elif isinstance(meas, int | float):
        var = {y: float(meas) for y in model.outputs}
    else:
        unknown = [k for k in meas if k not in model.outputs]
        missing = [y for y in model.outputs if y not in meas]
        if unknown or missing:
            raise DataError(f"config: [{where}.noise].measurement: unknown outputs {unknown}, missing "
                            f"{missing} (outputs: {model.outputs})")
        var = {y: float(meas[y]) for y in model.outputs}
    bad = {k: v for k, v in var.items() if not (math.isfinite(v) and v > 0)}
    if bad:
        raise DataError(f"config: [{where}.noise]: measurement variances must be > 0 and finite, got {bad}")
    proc = spec.get("process", 1e-8)
    q = np.broadcast_to(np.asarray(proc, dtype=float), (model.n_states,)).copy() if np.ndim(proc) == 0 or \
        np.size(proc) == model.n_states else None
    if q is None or not np.all(np.isfinite(q)) or np.any(q < 0):
        raise DataError(f"config: [{where}.noise].process must be one variance >= 0 or {model.n_states} of "
                        f"them, got {proc!r}")
    return {"measurement": var, "process": q}


@dataclass(frozen=True)
class AlarmTarget:
    """A false-alarm target with explicit semantics, those of :func:`~fdikit.detect.design_threshold`.

    Per ``"hour"``, ``pfa`` is the expected number of false alarms (alarm onsets: an episode
    counts once) per hour of operation, any rate ``> 0`` (``1.0``: one an hour). Per ``"sample"``
    it is the probability that a sample is alarmed, per ``"run"`` the probability of at least one
    false alarm in a run of ``run_length`` seconds, both in (0, 1). ``hold`` samples over the
    threshold make an alarm. :meth:`per_sample` converts it, for a sample time ``dt``, to the
    per-sample probability of a new alarm: ``pfa dt / 3600`` per hour, ``1 - (1 - pfa)^(dt / T)``
    per run of ``T`` s.

    Examples
    --------
    >>> a = AlarmTarget(1e-3, "hour")
    >>> f"{a.per_sample(0.01):.3e}"
    '2.778e-09'
    >>> AlarmTarget(1.0, "hour").per_sample(0.01) * 3600 / 0.01     # one expected alarm an hour
    1.0
    """

    pfa: float
    per: str = "sample"
    run_length: float | None = None
    hold: int = 1

    def __post_init__(self):
        if self.per not in ("sample", "run", "hour"):
            raise DataError(f"per must be 'sample', 'run' or 'hour', got {self.per!r}")
        if self.per == "hour" and not (0 < self.pfa < math.inf):
            raise DataError(f"the false-alarm target per hour is an expected number of false alarms "
                            f"per hour of operation, > 0 and finite; got pfa = {self.pfa}")
        if self.per != "hour" and not (0 < self.pfa < 1):
            raise DataError(f"the false-alarm target per {self.per} is a probability: pfa must lie in "
                            f"(0, 1), got {self.pfa}")
        if self.per == "run" and not (self.run_length and self.run_length > 0):
            raise DataError("a per-run target needs run_length (s) > 0")
        if int(self.hold) != self.hold or self.hold < 1:
            raise DataError(f"hold must be an integer >= 1, got {self.hold}")

    def span(self, dt: float) -> float:
        """Seconds the target refers to (one sample, one run or one hour)."""
        return {"sample": float(dt), "run": float(self.run_length or 0.0), "hour": 3600.0}[self.per]

    def per_sample(self, dt: float) -> float:
        """The per-sample probability of a new false alarm that meets the target (per hour: the
        expected onsets per sample, ``pfa dt / 3600``, at most 1)."""
        if not dt > 0:
            raise DataError(f"the sample time must be > 0, got {dt}")
        if self.per == "hour":
            return float(min(self.pfa * float(dt) / 3600.0, 1.0))
        n = self.span(dt) / float(dt)
        return float(-math.expm1(math.log1p(-self.pfa) / max(n, 1.0)))


def alarm_from_config(design: Mapping[str, Any], *, where: str = "design") -> AlarmTarget:
    """The :class:`AlarmTarget` of ``[design.alarm]`` (default: 1e-3 expected false alarms per hour,
    hold 5)."""
    spec = _check(design.get("alarm", {}), DESIGN_KEYS["alarm"], f"{where}.alarm")
    run_length = None if "run_length" not in spec else float(spec["run_length"])
    return AlarmTarget(float(spec.get("pfa", 1e-3)), str(spec.get("per", "hour")), run_length,
                       int(spec.get("hold", 5)))


# ------------------------------------------------------------------------------ the whole monitor
#: Artifact names of a declarative design, in the order the monitor runs them.
GENERATORS = ["bank"]
PROCESSORS = ["features", "hold", "isolate"]


def processors_for(design: Mapping[str, Any], *, where: str = "design") -> list[str]:
    """The processor artifacts of a declarative design: :data:`PROCESSORS`, with ``"smooth"`` (the
    EWMA of the features) before the hold when ``[design.detect]`` smoothing = "ewma"."""
    from .declarative_smoothing import smoothing_from_config

    if smoothing_from_config(design, where=where).active:
        return ["features", "smooth", "hold", "isolate"]
    return list(PROCESSORS)


def sample_time(design: Mapping[str, Any], model: LinearFaultModel, *, where: str = "design") -> float:
    """The monitor's sample time: ``[design].sample_time``, or the discrete plant's ``dt``."""
    dt = design.get("sample_time")
    if dt is None:
        if model.dt is None:
            raise DataError(f"config: [{where}].sample_time (s) is needed for a continuous-time plant")
        return float(model.dt)
    dt = float(dt)
    if not (dt > 0 and math.isfinite(dt)):
        raise DataError(f"config: [{where}].sample_time must be a positive number of seconds, got {dt}")
    if model.dt is not None and abs(model.dt - dt) > 1e-9 * dt:
        raise DataError(f"config: [{where}].sample_time = {dt} s but the plant is discrete with "
                        f"dt = {model.dt} s")
    return dt


def design_monitor(design: Mapping[str, Any], base_dir: str | Path = ".", *, where: str = "design",
                   nominal_hours: float | None = None, seed: int = 0,
                   log: Mapping[str, Any] | None = None,
                   nominal: Sequence[Signals] | Mapping[str, Signals] | None = None) -> dict[str, Any]:
    """Design the whole monitor of a declarative ``[design]`` table: residual bank, features,
    thresholds for the false-alarm target, and isolation by the fault signature.

    1. The plant, faults, disturbances and noise of the config (:func:`plant_from_config`,
       :func:`noise_from_config`).
    2. A residual bank (:func:`fdikit.residuals.design_residual_bank`): structured residuals, each
       decoupled from the disturbances and from the faults ``[design.structure]`` names for it (or
       the default scheme), observer weights from the noise, the design-time sensitivity check
       (a weak residual/fault pair is a :class:`~fdikit.residuals.SensitivityWarning` naming both).
    3. Features: the norm of each residual's channels, whitened by their nominal covariance
       (``|r|`` is then a chi statistic of the residual's dimension).
    4. Thresholds (:func:`fdikit.detect.design_threshold`) for ``[design.alarm]`` (per sample, run
       or hour, hold ``Z``; family-wise over the residuals) from simulated nominal operation: the
       residuals are decoupled from the known inputs, so the plant is simulated with its noise only
       (``nominal_hours`` of it, default 0.05 h in 20 runs). Where those data cannot show a rate as
       small as the target (slow residuals are strongly autocorrelated), the threshold is the
       Gaussian bound instead: each feature is the norm of a whitened Gaussian residual of
       dimension ``k``, chi-distributed, and its ``1 - p`` quantile (``p`` the per-sample target,
       Bonferroni over the residuals) bounds the samples over the threshold, hence the alarms.
       That fallback is announced with a :class:`UserWarning` naming the target, the data and
       why, and the report says which method set each threshold and why. These rates are
       model-based (``report["rates"]``): they hold if the plant and its noise are as declared.
       Given ``nominal`` logs (``[design].nominal_log``), the whitening and the thresholds are set
       on the residuals of those real logs instead, time-blocked: each log's first half fits them,
       its second half measures every claimed rate, and a design whose measured interval misses
       its claimed one is refused unless ``[design].accept_miscalibrated = true``
       (:func:`fdikit.monitor.declarative_thresholds.logged_thresholds`).
    5. Isolation: :class:`fdikit.isolate.SignatureDecision` on the alarms with the bank's signature.

    Returns
    -------
    dict
        The artifacts ``bank`` (FilterDesign), ``features`` (FeatureNorms), ``hold`` (Hold) and
        ``isolate`` (SignatureDecision), and ``report`` (a plain dict: signature, isolability,
        weak pairs, threshold design, ``claims``: every stated false-alarm rate with its interval,
        and measured on held-out data with real logs; see
        :mod:`fdikit.monitor.declarative_thresholds`) under the key ``"_report"``.

    Parameters
    ----------
    design : mapping
        The ``[design]`` table.
    base_dir : path
        The config's folder (relative paths).
    where : str
        The table's name in error messages.
    nominal_hours : float, optional
        Simulated nominal operation for the model-based thresholds (default 0.05 h).
    seed : int
        Seed of that simulation.
    log : mapping, optional
        The config's ``[log]`` table: how the identification and noise logs are read.
    nominal : sequence of Signals or dict name -> Signals, optional
        Real nominal logs in monitor channels: the thresholds are set and checked on them.
    """
    import warnings

    from ..detect import Hold
    from ..isolate import SignatureDecision
    from ..residuals import design_residual_bank
    from .declarative_smoothing import smoothing_from_config
    from .declarative_thresholds import logged_thresholds, simulated_thresholds

    smoothing = smoothing_from_config(design, where=where)
    model, ident, id_logs = _plant(design, base_dir, where, log)
    noise = noise_from_config(design, model, base_dir, where=where, identification=ident, log=log)
    alarm = alarm_from_config(design, where=where)
    dt = sample_time(design, model, where=where)
    structure = design.get("structure") or None
    R = np.array([noise["measurement"][y] for y in model.outputs])
    Q = np.asarray(noise["process"], float)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        bank = design_residual_bank(model, dt, structure, noise={"process": Q, "measurement": R})
    weak = [str(w.message) for w in caught]
    for w in caught:
        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    raw = bank.design
    # one feature (norm) per residual; a residual of one channel would give the feature its
    # channel's name, and the monitor refuses two channels of one name: ":norm" then
    chans_of = {name: bank.channels(name) for name in bank.residual_names}
    taken = set(bank.design.residual_names)
    groups = {(f"{name}:norm" if name in taken else name): ch for name, ch in chans_of.items()}
    md = model.discretize(dt) if model.dt is None else model
    if not nominal and id_logs:
        # an identified plant: the nominal logs it was identified from, in its deviation variables,
        # carry the model's own error (closed-loop bias, sensors held between slow messages), which
        # noise simulated from the model does not
        implicit = _deviation_logs(ident, id_logs, [*raw.u_names, *raw.y_names])
    else:
        implicit = None
    if nominal or implicit:   # real nominal logs: thresholds set and measured on them, time-blocked
        th = logged_thresholds(raw, groups, alarm, dt, nominal or implicit,
                               accept_miscalibrated=bool(design.get("accept_miscalibrated", False)),
                               fallback=not nominal,
                               source="[design].nominal_log" if nominal else
                               "the logs the plant was identified from ([design.plant].identify.logs)",
                               smoothing=smoothing,
                               in_sample=_in_sample(design, base_dir, ident, nominal or implicit, implicit))
    elif smoothing.active:
        raise DataError(f"config: [{where}.detect].smoothing = \"ewma\" sets its limits on real nominal "
                        f"logs: give [{where}].nominal_log (or identify the plant from logs)")
    else:         # simulated noise of the declared model: the rates are model-based
        th = simulated_thresholds(md, raw, groups, R, Q, alarm, dt, nominal_hours=nominal_hours, seed=seed)
    white, feats, thr, td = th["white"], th["features"], th["thr"], th["td"]
    names = th.get("names") or list(feats.output_names)
    hold = Hold(names, thr if thr.size > 1 else float(thr[0]), Z=alarm.hold, absolute=True)
    sig = bank.signature
    iso = SignatureDecision(np.asarray(sig.matrix, int), list(sig.faults), hold.output_names)
    report = {"faults": list(sig.faults), "residuals": list(bank.residual_names),
              "signature": np.asarray(sig.matrix, int).tolist(), "isolability": str(bank.isolability()),
              "weak": weak, "sample_time": dt,
              "alarm": {"pfa": alarm.pfa, "per": alarm.per, "hold": alarm.hold},
              "thresholds": dict(zip(names, thr.tolist() if thr.size > 1 else [float(thr[0])] * len(names))),
              "threshold_design": {k: v for k, v in td.items() if k != "threshold"
                                   and not isinstance(v, np.ndarray)},
              "claims": th["claims"]}
    if nominal or implicit:
        report.update(rates="measured on held-out nominal logs",
                      threshold_source="nominal logs" if nominal else "the identification's nominal logs",
                      nominal_records=th["records"], nominal_hours_fit=th["fit_hours"],
                      nominal_hours_measured=th["measure_hours"],
                      split="each log's first half (after the filter's warm-up) fits the whitening and the "
                            "thresholds; its second half measures them; with two records or more, each "
                            "record is also left out in turn (refitted without it, measured on it); samples "
                            "the plant was identified on (in_sample) neither fit nor measure",
                      in_sample=th["in_sample"], record_check=th["record_check"],
                      accepted_miscalibrated=any(c.get("verdict", "inside") != "inside"
                                                 for c in th["claims"]))
    else:
        report.update(rates="model-based", threshold_source="simulated noise of the declared model",
                      nominal_hours_simulated=th["runs"] * th["duration"] / 3600.0)
    if ident is not None:
        i = ident.info
        report["identification"] = {k: i[k] for k in ("method", "order", "criterion", "order_scores", "fit",
                                                      "fit_per_record", "u_offset", "y_offset", "records",
                                                      "integrators", "kalman") if k in i}
    if th.get("smooth") is not None:
        report["smoothing"] = td["smoothing"]
        return {"bank": white, "features": feats, "smooth": th["smooth"], "hold": hold, "isolate": iso,
                "_report": report}
    return {"bank": white, "features": feats, "hold": hold, "isolate": iso, "_report": report}


def _in_sample(design: Mapping[str, Any], base_dir: str | Path, ident: Any, logs: Any,
               implicit: Any) -> dict[str, int]:
    """Threshold log name -> the leading samples the plant was identified on (estimated from): the
    identification's own logs, and a ``[design].nominal_log`` that is one of them (same file)."""
    if ident is None or not isinstance(logs, Mapping):
        return {}
    per_rec = list(ident.info.get("estimation_samples_per_record") or [])
    if implicit:
        return {f"identification log {k}": n for k, n in enumerate(per_rec)}
    spec = design["plant"]["identify"]
    files = [spec["logs"]] if isinstance(spec["logs"], str) else list(spec["logs"])
    own = {}
    for k, f in enumerate(files[:len(per_rec)]):
        own[Path(config_path(base_dir, f, where="[design.plant].identify.logs")).resolve()] = per_rec[k]
    out = {}
    for name in logs:
        try:
            p = Path(name).resolve()
        except (OSError, ValueError):
            continue
        if p in own:
            out[name] = own[p]
    return out


def _deviation_logs(ident: Any, logs: Sequence[Signals], names: list[str]) -> dict[str, Signals]:
    """The identification logs in the identified model's deviation variables (each channel minus the
    identification's operating point), named for messages."""
    off = {**ident.info["u_offset"], **ident.info["y_offset"]}
    out = {}
    for k, log in enumerate(logs):
        v = log.values[:, :, log.index(names)] - np.array([off[n] for n in names])
        out[f"identification log {k}"] = Signals(log.t, v, names, check=False)
    return out


def decision_for(design: Mapping[str, Any]) -> dict[str, Any]:
    """The ``[decision]`` table a declarative design implies: one announcement per isolated fault."""
    faults = list(_check(design.get("faults", {}), DESIGN_KEYS["faults"], "design.faults").get("names", []))
    chans = [f"fault:{f}" for f in faults]
    return {"channels": chans, "level": 0.75, "names": dict(zip(chans, faults))}
