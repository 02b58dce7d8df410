"""Design artifacts: every design saved as data, versioned and self-describing, never pickled.

Luo et al.'s point: thresholds and designs are *data*, uploaded to a vehicle without
changing the diagnostic software. An artifact is two files with one stem:

* ``NAME.json`` -- the manifest: format version, fdikit version, kind (the class), the channel
  names (and units) the design reads and writes, free metadata, and the design's structure with
  every scalar, name and small matrix as JSON (Python's ``repr`` of a float round-trips
  exactly, so nothing is lost);
* ``NAME.npz`` -- the design's NumPy arrays, when its ``to_dict`` returns any (loaded with
  ``allow_pickle=False``).

A kind is any class of fdikit with ``to_dict()`` and ``from_dict(d)``: the manifest records its
``module:qualname`` (only modules inside ``fdikit`` are ever imported on loading); the short names
in :data:`KINDS` are kept for readability and for artifacts written before the class path was
recorded.

JSON keeps an artifact readable, diffable and editable by an engineer; NPZ keeps large arrays
(e.g. support vectors) compact and exact. Loading checks the format
version and, when asked, the channel names, and refuses a mismatch with a clear message.
"""

from __future__ import annotations

import importlib
import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import DataError
from .state import _atomic_write, _flatten, _unflatten

__all__ = ["ARTIFACT_FORMAT", "KINDS", "MOVED", "artifact_channels", "load_artifact", "moved",
           "save_artifact"]

#: Version of the artifact layout; a different major version is refused on loading.
ARTIFACT_FORMAT = "fdikit-artifact/1"

#: Registered kinds: class name -> "module:attribute".
KINDS: dict[str, str] = {
    "ObserverDesign": "fdikit.residuals.observer:ObserverDesign",
    "FilterDesign": "fdikit.residuals.fdf:FilterDesign",
    "SlidingModeReconstructor": "fdikit.residuals.smo:SlidingModeReconstructor",
    "GLRT": "fdikit.detect.glrt:GLRT",
    "TimeGated": "fdikit.detect.glrt:TimeGated",
    "Hold": "fdikit.detect.threshold:Hold",
    "MHSSPT": "fdikit.detect.mhsspt:MHSSPT",
    "DMatrix": "fdikit.isolate.dmatrix:DMatrix",
    "DiagnosticTree": "fdikit.isolate.sequencing:DiagnosticTree",
    "SVMDecision": "fdikit.isolate.svm:SVMDecision",
}


#: Where code of an older package layout lives now: old module (or ``module:Class``) -> new one.
#: Artifacts and recipes saved before the layout changed name the old paths; :func:`moved` maps
#: them (longest prefix first), so they still load.
MOVED: dict[str, str] = {
    # the papers' systems left the generic layers (issue 14)
    "fdikit.plants.passenger_car.monitor:FeatureNorms": "fdikit.detect.features:FeatureNorms",
    "fdikit.plants.passenger_car.monitor:WarmupMHSSPT": "fdikit.detect.mhsspt:WarmupMHSSPT",
    "fdikit.evaluate.campaign:TestBank": "fdikit.detect.bank:TestBank",
    "fdikit.evaluate.campaign:TestSpec": "fdikit.detect.bank:TestSpec",
    "fdikit.plants.passenger_car": "fdikit.systems.car",
    "fdikit.plants.abs": "fdikit.systems.abs.plant",
    "fdikit.plants.aircraft": "fdikit.systems.aircraft",
    "fdikit.plants.two_mass": "fdikit.systems.two_mass",
    "fdikit.residuals.abs_residuals": "fdikit.systems.abs.residuals",
    "fdikit.evaluate.abs_diagnoser": "fdikit.systems.abs.diagnoser",
    "fdikit.evaluate.abs_config": "fdikit.systems.abs.recipe",
    "fdikit.evaluate.campaign": "fdikit.systems.abs.campaign",
    "fdikit.commands.reconstruct": "fdikit.systems.aircraft.reconstruction",
    "fdikit.monitor.artifacts": "fdikit.base.artifacts",
    "fdikit.monitor.state": "fdikit.base.state",
}


def moved(path: str) -> str:
    """The current location of ``"module"`` or ``"module:attribute"`` written by an older layout.

    Examples
    --------
    >>> moved("fdikit.plants.passenger_car.monitor_fused:FusedCarMonitor")
    'fdikit.systems.car.monitor_fused:FusedCarMonitor'
    >>> moved("fdikit.plants.passenger_car.monitor:FeatureNorms")
    'fdikit.detect.features:FeatureNorms'
    >>> moved("fdikit.detect.glrt:GLRT")
    'fdikit.detect.glrt:GLRT'
    """
    path = str(path)
    if path in MOVED:
        return MOVED[path]
    mod, sep, attr = path.partition(":")
    for old in sorted(MOVED, key=len, reverse=True):
        if ":" not in old and (mod == old or mod.startswith(old + ".")):
            return MOVED[old] + mod[len(old):] + sep + attr
    return path


def _class_path(obj: Any) -> str | None:
    """``module:qualname`` of a design class defined inside fdikit with to_dict/from_dict, else None."""
    cls = type(obj)
    if cls.__name__ in KINDS:
        return KINDS[cls.__name__]
    if (cls.__module__.split(".")[0] == "fdikit" and callable(getattr(cls, "to_dict", None))
            and callable(getattr(cls, "from_dict", None))):
        return f"{cls.__module__}:{cls.__qualname__}"
    return None


def _resolve(kind: str, where: str | None = None) -> type:
    """The class of an artifact: a registered kind, or the fdikit class path the manifest records.

    Only modules inside the ``fdikit`` package are ever imported (an artifact cannot name code
    from elsewhere), and the class must provide ``from_dict``.
    """
    target = KINDS.get(kind) or (moved(where) if where else where)
    if not target:
        raise DataError(f"unknown artifact kind {kind!r}; known kinds: {sorted(KINDS)}")
    mod, _, attr = str(target).partition(":")
    if mod.split(".")[0] != "fdikit" or not attr:
        raise DataError(f"artifact kind {kind!r}: class {target!r} is not an fdikit design class; "
                        "refusing to import it")
    try:
        obj: Any = importlib.import_module(mod)
        for part in attr.split("."):
            obj = getattr(obj, part)
    except (ImportError, AttributeError) as exc:
        raise DataError(f"artifact kind {kind!r} ({target}) is not available here ({exc})") from None
    if not callable(getattr(obj, "from_dict", None)):
        raise DataError(f"artifact kind {kind!r} ({target}) has no from_dict")
    return obj


def artifact_channels(obj: Any) -> dict[str, list[str]]:
    """Channel names a design reads (``inputs``) and writes (``outputs``), where it has them."""
    ins: list[str] = []
    for attr in ("u_names", "y_names", "input_names"):
        ins += [str(s) for s in getattr(obj, attr, None) or [] if str(s) not in ins]
    outs: list[str] = []
    for attr in ("residual_names", "output_names"):
        v = getattr(obj, attr, None)
        if v:
            outs = [str(s) for s in v]
            break
    return {"inputs": ins, "outputs": outs}


def _stem(path: str | os.PathLike) -> Path:
    p = Path(path)
    return p.with_suffix("") if p.suffix in (".json", ".npz") else p


def save_artifact(path: str | os.PathLike, obj: Any, *, meta: dict | None = None,
                  units: dict[str, str] | None = None) -> Path:
    """Save a design as ``<stem>.json`` (+ ``<stem>.npz`` when it has arrays); returns the JSON path.

    Examples
    --------
    >>> import os, tempfile
    >>> from fdikit.detect import Hold
    >>> p = save_artifact(os.path.join(tempfile.mkdtemp(), "hold"), Hold(["r"], 0.5, Z=3))
    >>> h = load_artifact(p, expect_inputs=["r"])
    >>> (h.Z, float(h.threshold[0]))
    (3, 0.5)
    """
    kind = type(obj).__name__
    where = _class_path(obj)
    if where is None:
        raise DataError(f"{kind} is not an artifact kind (registered: {sorted(KINDS)}; any fdikit class "
                        "with to_dict/from_dict also is)")
    from .. import __version__

    arrays: dict[str, np.ndarray] = {}
    payload = _flatten(obj.to_dict(), "p", arrays)
    stem = _stem(path)
    manifest = {
        "format": ARTIFACT_FORMAT,
        "fdikit_version": __version__,
        "kind": kind,
        "class": where,
        "channels": artifact_channels(obj),
        "units": dict(units or {}),
        "meta": dict(meta or {}),
        "arrays": {k: f"a{i}" for i, k in enumerate(arrays)},
        "payload": payload,
    }
    if arrays:
        stored = {f"a{i}": a for i, a in enumerate(arrays.values())}
        _atomic_write(stem.with_suffix(".npz"), lambda fh: np.savez(fh, **stored))
    text = json.dumps(manifest, indent=1, allow_nan=True)
    _atomic_write(stem.with_suffix(".json"), lambda fh: fh.write(text.encode()))
    return stem.with_suffix(".json")


def load_artifact(path: str | os.PathLike, *, kind: str | None = None,
                  expect_inputs: list[str] | None = None,
                  expect_outputs: list[str] | None = None) -> Any:
    """Load a design saved by :func:`save_artifact`.

    Parameters
    ----------
    kind : str, optional
        Refuse an artifact of another kind.
    expect_inputs, expect_outputs : list of str, optional
        Refuse an artifact whose channel names differ (a design from another model).
    """
    stem = _stem(path)
    jpath = stem.with_suffix(".json")
    try:
        manifest = json.loads(jpath.read_text())
    except FileNotFoundError:
        raise DataError(f"{jpath}: no such artifact") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise DataError(f"{jpath}: not a readable artifact ({exc})") from None
    if not isinstance(manifest, dict) or "format" not in manifest:
        raise DataError(f"{jpath}: not an fdikit artifact (no format field)")
    fmt = str(manifest["format"])
    if fmt.split("/")[0] != ARTIFACT_FORMAT.split("/")[0] or fmt != ARTIFACT_FORMAT:
        raise DataError(f"{jpath}: artifact format {fmt!r}, this fdikit reads {ARTIFACT_FORMAT!r}")
    k = manifest.get("kind")
    if kind is not None and k != kind:
        raise DataError(f"{jpath}: artifact is a {k}, expected a {kind}")
    ch = manifest.get("channels", {})
    for what, want in (("inputs", expect_inputs), ("outputs", expect_outputs)):
        if want is not None and list(ch.get(what, [])) != list(want):
            raise DataError(f"{jpath}: the design's {what} are {ch.get(what)}, but {list(want)} were "
                            "expected (a design for another model or channel map?)")
    arrays: dict[str, np.ndarray] = {}
    if manifest.get("arrays"):
        npz = stem.with_suffix(".npz")
        try:
            with np.load(npz, allow_pickle=False) as z:
                arrays = {key: z[stored] for key, stored in manifest["arrays"].items()}
        except (OSError, ValueError, KeyError) as exc:
            raise DataError(f"{npz}: arrays of the artifact are missing or unreadable ({exc})") from None
    cls = _resolve(str(k), manifest.get("class"))
    try:
        return cls.from_dict(_unflatten(manifest["payload"], arrays))
    except (KeyError, TypeError, ValueError) as exc:
        raise DataError(f"{jpath}: a {k} cannot be rebuilt from this artifact ({exc!r})") from None
