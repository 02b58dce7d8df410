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
(e.g. support vectors) compact and exact. Loading checks, and refuses with a
:class:`~fdikit.errors.DataError` naming the key:

* the format version;
* the fdikit version: an artifact written by a *newer* fdikit than the one installed is refused
  (it may hold fields this version would silently ignore); upgrade fdikit or rerun the design;
* the manifest against the payload: every array the manifest lists is in the NPZ file with the
  shape and dtype the manifest records, no payload entry names an array the manifest does not
  list, and the ``channels`` recorded equal those of the
  rebuilt design (an edited channel list would otherwise load without a word);
* when asked, the channel names a caller expects.

``meta`` is free data for the producer: :func:`fdikit.monitor.config.run_design` stamps
``design_hash`` there (the hash of the config's ``[design]`` section), and
:func:`~fdikit.monitor.config.build_monitor` refuses a design made from another one.
"""

from __future__ import annotations

import importlib
import json
import os
import sys
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import DataError
from .state import _atomic_write, _flatten, _unflatten

__all__ = ["ARTIFACT_FORMAT", "KINDS", "MOVED", "artifact_channels", "load_artifact", "moved",
           "read_manifest", "save_artifact", "version_tuple"]

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
        return f"{_public_module(cls)}:{cls.__qualname__}"
    return None


def _public_module(cls: type) -> str:
    """The shortest enclosing package that re-exports ``cls`` under its name (else its own module).

    A module split into a package of one-concept submodules (wave 3) keeps its classes importable
    from the package; recording that path keeps an artifact's manifest the same across such
    splits, so it loads in the fdikit that wrote it, in older ones and in later layouts alike.
    Only packages below a layer (``fdikit.detect.sensor``, not ``fdikit.detect``) or below a
    system (``fdikit.systems.car.monitor_rav4``) are tried: the module paths of the layout before.
    """
    parts = cls.__module__.split(".")
    if "." in cls.__qualname__:   # a nested class lives where its outer class lives
        return cls.__module__
    best = cls.__module__
    floor = 4 if parts[:2] == ["fdikit", "systems"] else 3
    for i in range(len(parts) - 1, floor - 1, -1):
        mod = sys.modules.get(".".join(parts[:i]))
        if mod is None or getattr(mod, cls.__name__, None) is not cls:
            break
        best = ".".join(parts[:i])
    return best


def _resolve(kind: str, where: str | None = None) -> type:
    """The class of an artifact: a registered kind, or the fdikit class path the manifest records.

    Only modules inside the ``fdikit`` package are ever imported (an artifact cannot name code
    from elsewhere), and the class must provide ``from_dict``.
    """
    if where and str(moved(where)).partition(":")[0].split(".")[0] != "fdikit":
        raise DataError(f"artifact kind {kind!r}: key 'class' names {where!r}, which is not an fdikit design "
                        "class; refusing to import it")
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


def version_tuple(version: str) -> tuple[int, ...]:
    """The leading numeric release of a version string (trailing zeros dropped, so 1.0 == 1.0.0),
    without the ``packaging`` library.

    Examples
    --------
    >>> version_tuple("0.10.2"), version_tuple("1.2.dev3"), version_tuple("2.0rc1+local")
    ((0, 10, 2), (1, 2), (2,))
    >>> version_tuple("0.1.0") < version_tuple("0.10")
    True
    """
    out: list[int] = []
    for part in str(version).split("+")[0].split("."):
        digits = ""
        for ch in part:
            if not ch.isdigit():
                break
            digits += ch
        if not digits:
            break
        out.append(int(digits))
        if len(digits) != len(part):
            break
    while len(out) > 1 and out[-1] == 0:
        out.pop()
    return tuple(out)


def save_artifact(path: str | os.PathLike, obj: Any, *, meta: dict | None = None,
                  units: dict[str, str] | None = None) -> Path:
    """Save a design as ``<stem>.json`` (+ ``<stem>.npz`` when it has arrays); returns the JSON path.

    Parameters
    ----------
    path : path-like
        Stem of the artifact (``.json`` / ``.npz`` are added); a missing folder is created.
    obj : object
        A design: a registered kind or any fdikit class with ``to_dict`` / ``from_dict``.
    meta : dict, optional
        Free JSON-able data stored in the manifest (e.g. ``design_hash``).
    units : dict, optional
        Channel name -> unit, for the record.

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
        "shapes": {k: {"shape": list(a.shape), "dtype": str(a.dtype)} for k, a in arrays.items()},
        "payload": payload,
    }
    if arrays:
        stored = {f"a{i}": a for i, a in enumerate(arrays.values())}
        _atomic_write(stem.with_suffix(".npz"), lambda fh: np.savez(fh, **stored), mkdir=True)
    text = json.dumps(manifest, indent=1, allow_nan=True)
    _atomic_write(stem.with_suffix(".json"), lambda fh: fh.write(text.encode()), mkdir=True)
    return stem.with_suffix(".json")


def read_manifest(path: str | os.PathLike) -> dict:
    """The manifest (JSON) of an artifact, checked for its format and fdikit version only.

    Raises
    ------
    DataError
        A missing or unreadable file, another artifact format, or an artifact written by a newer
        fdikit than the one installed (naming both versions).
    """
    jpath = _stem(path).with_suffix(".json")
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
    from .. import __version__

    mine, theirs = version_tuple(__version__), version_tuple(str(manifest.get("fdikit_version", "")))
    if mine and mine != (0,) and theirs and theirs > mine:
        raise DataError(f"{jpath}: key 'fdikit_version': the artifact was written by fdikit "
                        f"{manifest.get('fdikit_version')}, newer than the installed {__version__}; it may "
                        "hold design data this version would ignore. Upgrade fdikit, or rerun the design "
                        "(fdikit design CONFIG) with this version")
    for key, typ in (("channels", dict), ("meta", dict), ("arrays", dict), ("units", dict)):
        if key in manifest and not isinstance(manifest[key], typ):
            raise DataError(f"{jpath}: key {key!r} must be a JSON object, got {type(manifest[key]).__name__}")
    return manifest


def _array_refs(d: Any, out: set[str]) -> set[str]:
    """The array keys a flattened payload refers to."""
    if isinstance(d, dict):
        if "__array__" in d:
            out.add(str(d["__array__"]))
        for v in d.values():
            _array_refs(v, out)
    elif isinstance(d, list):
        for v in d:
            _array_refs(v, out)
    return out


def load_artifact(path: str | os.PathLike, *, kind: str | None = None,
                  expect_inputs: list[str] | None = None,
                  expect_outputs: list[str] | None = None) -> Any:
    """Load a design saved by :func:`save_artifact`, checking the manifest against the payload.

    Parameters
    ----------
    path : path-like
        The artifact (its stem, or the ``.json`` / ``.npz`` file).
    kind : str, optional
        Refuse an artifact of another kind.
    expect_inputs, expect_outputs : list of str, optional
        Refuse an artifact whose channel names differ (a design from another model).

    Raises
    ------
    DataError
        See the module docstring: each check names the key that disagrees.
    """
    stem = _stem(path)
    jpath = stem.with_suffix(".json")
    manifest = read_manifest(jpath)
    k = manifest.get("kind")
    if kind is not None and k != kind:
        raise DataError(f"{jpath}: artifact is a {k}, expected a {kind}")
    ch = manifest.get("channels", {})
    for what, want in (("inputs", expect_inputs), ("outputs", expect_outputs)):
        if want is not None and list(ch.get(what, [])) != list(want):
            raise DataError(f"{jpath}: the design's {what} are {ch.get(what)}, but {list(want)} were "
                            "expected (a design for another model or channel map?)")
    if "payload" not in manifest:
        raise DataError(f"{jpath}: key 'payload' is missing (the design itself)")
    listed = dict(manifest.get("arrays") or {})
    unlisted = sorted(_array_refs(manifest["payload"], set()) - set(listed))
    if unlisted:
        raise DataError(f"{jpath}: the payload refers to arrays {unlisted} that key 'arrays' does not list")
    arrays: dict[str, np.ndarray] = {}
    if listed:
        npz = stem.with_suffix(".npz")
        try:
            with np.load(npz, allow_pickle=False) as z:
                missing = [key for key, stored in listed.items() if stored not in z.files]
                if missing:
                    raise DataError(f"{npz}: arrays {missing} listed under key 'arrays' of {jpath.name} are "
                                    f"not in the NPZ file (it holds {sorted(z.files)})")
                extra = sorted(set(z.files) - set(listed.values()))
                if extra:
                    raise DataError(f"{npz}: the NPZ file holds arrays {extra} that key 'arrays' of "
                                    f"{jpath.name} does not list: the arrays do not belong to this manifest")
                arrays = {key: z[stored] for key, stored in listed.items()}
        except DataError:
            raise
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as exc:
            raise DataError(f"{npz}: arrays of the artifact are missing, corrupt or unreadable "
                            f"({type(exc).__name__}: {exc})") from None
        shapes = manifest.get("shapes")
        if isinstance(shapes, dict):   # artifacts written before shapes were recorded have none
            for key, a in arrays.items():
                rec = shapes.get(key)
                if rec is None:
                    raise DataError(f"{jpath}: array {key!r} has no entry under key 'shapes'")
                if list(rec.get("shape", [])) != list(a.shape) or str(rec.get("dtype")) != str(a.dtype):
                    raise DataError(f"{jpath}: array {key!r} is {a.dtype} of shape {list(a.shape)} in "
                                    f"the NPZ file, but key 'shapes' records {rec.get('dtype')} of shape "
                                    f"{rec.get('shape')}: the manifest and the arrays disagree")
    cls = _resolve(str(k), manifest.get("class"))
    try:
        obj = cls.from_dict(_unflatten(manifest["payload"], arrays))
    except (KeyError, TypeError, ValueError, IndexError) as exc:
        raise DataError(f"{jpath}: a {k} cannot be rebuilt from this artifact ({exc!r})") from None
    got = artifact_channels(obj)
    for what in ("inputs", "outputs"):
        if what in ch and list(ch[what]) != got[what]:
            raise DataError(f"{jpath}: key 'channels.{what}' lists {list(ch[what])}, but the design in the "
                            f"payload has {got[what]}: the manifest was edited or does not belong to "
                            "this payload")
    return obj
