"""Planning a fleet run: the log files named by directories, globs or list files, each log's name,
vehicle and route (from its path or a manifest) and where its results go (:class:`LogTask`).

A log is *done* (:func:`is_done`) once its summary and its events are committed in the output
directory; a rerun plans the same tasks and skips those.
"""

from __future__ import annotations

import csv
import glob
import hashlib
import json
import os
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath
from urllib.parse import quote

from ..errors import DataError

__all__ = ["LogTask", "discover", "is_done", "path_fields", "plan", "read_manifest"]

_LIST_SUFFIXES = (".txt", ".lst", ".list")


def _log_suffixes() -> set[str]:
    from ..io.formats import FORMATS

    return {s for v in FORMATS.values() for s in v}


@dataclass
class LogTask:
    """One log of a fleet: where it is, what it is called, where its results go.

    Attributes
    ----------
    path : str
        Absolute path of the log file.
    log_id : str
        The log's path relative to where it was found (its name in the results).
    part : str
        File name stem of the log's result files (the log id made safe, plus a hash of the path).
    vehicle, route : str
        From the path (:func:`path_fields`) or the manifest (:func:`read_manifest`).
    fields : dict of str to str
        Further fields of the path template or the manifest.
    config : str
        Absolute path of the monitor configuration (TOML).
    out : str
        Absolute path of the output directory.
    stats : bool
        Also write every sample's residuals and statistics.

    Examples
    --------
    >>> LogTask("/logs/v1/r1.blf", "v1/r1.blf", "v1_r1_blf-0123456789", "v1", "r1").vehicle
    'v1'
    """

    path: str
    log_id: str
    part: str
    vehicle: str
    route: str
    fields: dict[str, str] = field(default_factory=dict)
    config: str = ""
    out: str = ""
    stats: bool = False


# ---------------------------------------------------------------------------------- finding logs
def discover(specs: list[str], *, exclude: Path | None = None) -> list[tuple[Path, PurePosixPath]]:
    """Log files named by directories, globs or list files: ``[(absolute path, relative path)]``.

    The relative path is from the directory searched (or the glob's fixed prefix, or the list
    file's directory); it is the log id. Duplicates (the same file found twice) are dropped.

    Parameters
    ----------
    specs : list of str
        Log files, directories (searched recursively for log files: BLF, ASC, candump, MDF4,
        Parquet, CSV; hidden files skipped), glob patterns (``"fleet/**/*.blf"``) or list files
        (``.txt`` / ``.lst`` / ``.list``: one path per line, relative to the list file, ``#``
        comments).
    exclude : Path, optional
        A directory whose files are never logs (the output directory).

    Returns
    -------
    list of (Path, PurePosixPath)

    Raises
    ------
    DataError
        A spec that names nothing, a pattern without a match, a list file naming a missing file.

    Examples
    --------
    >>> import tempfile
    >>> d = Path(tempfile.mkdtemp())
    >>> (d / "veh1").mkdir(); (d / "veh1" / "r1.csv").write_text("t,x")
    3
    >>> [str(rel) for _, rel in discover([str(d)])]
    ['veh1/r1.csv']
    """
    suffixes = _log_suffixes()
    found: list[tuple[Path, PurePosixPath]] = []

    def rel(p: Path, root: Path) -> PurePosixPath:
        try:
            return PurePosixPath(p.relative_to(root).as_posix())
        except ValueError:
            return PurePosixPath(p.name)

    for spec in specs:
        p = Path(spec)
        if any(c in spec for c in "*?["):
            fixed = []
            for part in Path(spec).parts:
                if any(c in part for c in "*?["):
                    break
                fixed.append(part)
            root = Path(*fixed) if fixed else Path(".")
            hits = sorted(Path(x) for x in glob.glob(spec, recursive=True))
            files = [h for h in hits if h.is_file()]
            if not files:
                raise DataError(f"the pattern {spec!r} matches no log file")
            found += [(f.resolve(), rel(f.resolve(), root.resolve())) for f in files]
        elif p.is_dir():
            files = sorted(f for f in p.rglob("*") if f.is_file() and f.suffix.lower() in suffixes
                           and not f.name.startswith("."))
            if exclude is not None:
                ex = exclude.resolve()
                files = [f for f in files if ex not in f.resolve().parents]
            found += [(f.resolve(), rel(f.resolve(), p.resolve())) for f in files]
        elif p.is_file() and p.suffix.lower() in _LIST_SUFFIXES:
            base = p.resolve().parent
            for n, line in enumerate(p.read_text().splitlines(), start=1):
                line = line.split("#", 1)[0].strip()
                if not line:
                    continue
                f = (base / line).resolve()
                if not f.is_file():
                    raise DataError(f"list file {str(p)!r} line {n}: no such log file {line!r}")
                found.append((f, rel(f, base)))
        elif p.is_file():
            found.append((p.resolve(), PurePosixPath(p.name)))
        else:
            raise DataError(f"{spec!r} is not a log file, a directory, a list file or a pattern that matches")
    seen, out = set(), []
    for f, r in found:
        if f not in seen:
            seen.add(f)
            out.append((f, r))
    return out


def read_manifest(path: str | os.PathLike) -> dict[Path, dict[str, str]]:
    """A manifest CSV (column ``path``, relative to the manifest, plus metadata columns) by absolute path.

    Parameters
    ----------
    path : path-like
        The manifest: a header with a ``path`` column and any of ``vehicle``, ``route`` and
        further columns.

    Returns
    -------
    dict of Path to dict of str to str
        Each log's absolute path to its other columns (stripped text).

    Raises
    ------
    DataError
        A missing file, not a CSV file, no ``path`` column, an empty path.

    Examples
    --------
    >>> import tempfile
    >>> d = Path(tempfile.mkdtemp())
    >>> (d / "m.csv").write_text(chr(10).join(["path,vehicle", "logs/a.blf,veh7"]))
    28
    >>> list(read_manifest(d / "m.csv").values())
    [{'vehicle': 'veh7'}]
    """
    p = Path(path)
    try:
        with open(p, newline="") as fh:
            rows = list(csv.DictReader(fh))
    except FileNotFoundError:
        raise DataError(f"manifest {str(p)!r} does not exist") from None
    except (UnicodeDecodeError, csv.Error) as exc:
        raise DataError(f"manifest {str(p)!r} is not a CSV file: {exc}") from None
    if not rows or "path" not in rows[0]:
        raise DataError(f"manifest {str(p)!r} needs a header with a 'path' column (and e.g. vehicle, route)")
    out = {}
    for n, row in enumerate(rows, start=2):
        if not (row.get("path") or "").strip():
            raise DataError(f"manifest {str(p)!r} line {n}: empty path")
        f = (p.resolve().parent / row["path"].strip()).resolve()
        out[f] = {k: (v or "").strip() for k, v in row.items() if k != "path" and k is not None}
    return out


def path_fields(rel: PurePosixPath, template: str) -> dict[str, str]:
    """Fields of a relative log path by a template such as ``"{vehicle}/{route}"``, matched from the end.

    Parameters
    ----------
    rel : PurePosixPath
        The log's relative path (its id).
    template : str
        Path components, ``{name}`` for a field and literal text that must match; the last
        component is the file name without its suffix.

    Returns
    -------
    dict of str to str
        The fields; empty when a literal component does not match.

    Examples
    --------
    >>> path_fields(PurePosixPath("fleet/veh07/2024-05-01/r3.blf"), "{vehicle}/{date}/{route}")
    {'route': 'r3', 'date': '2024-05-01', 'vehicle': 'veh07'}
    >>> path_fields(PurePosixPath("r3.blf"), "{vehicle}/{route}")
    {'route': 'r3'}
    """
    parts = [*rel.parent.parts, rel.name[: -len(rel.suffix)] if rel.suffix else rel.name]
    tpl = [t for t in template.strip("/").split("/") if t]
    out: dict[str, str] = {}
    for t, v in zip(reversed(tpl), reversed(parts)):
        if t.startswith("{") and t.endswith("}"):
            out[t[1:-1]] = v
        elif t != v:
            return {}
    return out


def _part_name(log_id: str, path: Path) -> str:
    safe = "".join(c if c.isalnum() or c in "-_" else "_" for c in log_id)[-80:]
    return f"{safe}-{hashlib.sha1(str(path).encode()).hexdigest()[:10]}"


def _part_dir(out: Path, kind: str, vehicle: str) -> Path:
    return out / kind / f"vehicle={quote(vehicle, safe='')}"


def plan(specs: list[str], config: str | os.PathLike, out: str | os.PathLike, *, manifest=None,
         template: str = "{vehicle}/{route}", stats: bool = False) -> list[LogTask]:
    """The tasks of a fleet run: every log found, named, with its vehicle, route and output parts.

    Parameters
    ----------
    specs : list of str
        Where the logs are (see :func:`discover`); files inside ``out`` are never logs.
    config : path-like
        The monitor configuration (TOML).
    out : path-like
        Output directory of the Parquet datasets.
    manifest : path-like, optional
        A manifest CSV (:func:`read_manifest`); its non-empty fields win over the path's.
    template : str
        How vehicle and route are read from a log's path (:func:`path_fields`). A log without
        a vehicle gets ``"unknown"``, without a route its file name without suffix.
    stats : bool
        Also write every sample's residuals and statistics.

    Returns
    -------
    list of LogTask

    Examples
    --------
    >>> import tempfile
    >>> d = Path(tempfile.mkdtemp())
    >>> (d / "veh1").mkdir(); (d / "veh1" / "r1.csv").write_text("t,x")
    3
    >>> [(t.log_id, t.vehicle, t.route) for t in plan([str(d)], d / "c.toml", d / "out")]
    [('veh1/r1.csv', 'veh1', 'r1')]
    """
    out = Path(out).resolve()
    meta = read_manifest(manifest) if manifest else {}
    depth = len([t for t in template.strip("/").split("/") if t])
    tasks, names = [], {}
    for path, rel in discover(specs, exclude=out):
        f = dict(path_fields(rel, template))
        given = {k: v for k, v in meta.get(path, {}).items() if v != ""}
        f.update(given)
        vehicle = f.pop("vehicle", "") or "unknown"
        route = f.pop("route", "") or (rel.name[: -len(rel.suffix)] if rel.suffix else rel.name)
        log_id = str(rel)
        if "vehicle" not in given:  # folders above the template's must not tell two vehicles apart
            key = (vehicle, json.dumps(f, sort_keys=True))   # whatever their routes are called
            above = rel.parts[:max(0, len(rel.parts) - depth)]
            other = names.setdefault(key, (log_id, above))
            if other[1] != above:
                raise DataError(
                    f"the logs {other[0]!r} and {log_id!r} both get vehicle {vehicle!r} "
                    f"from --path-fields {template!r}: their paths differ in folders the "
                    f"template does not read ({'/'.join(other[1]) or '.'} vs {'/'.join(above) or '.'}), "
                    f"so two vehicles would be merged; name every folder, e.g. --path-fields "
                    f"'{{vehicle}}/{{run}}/{{route}}', or give a --manifest")
        tasks.append(LogTask(str(path), log_id, _part_name(log_id, path), vehicle, route, f,
                             str(Path(config).resolve()), str(out), stats))
    return tasks


def is_done(task: LogTask, *, retry_errors: bool = False) -> bool:
    """Has this log been committed (its summary and its events are in place)?

    Parameters
    ----------
    task : LogTask
    retry_errors : bool
        Also call an error record not done (it is redone), and a summary that cannot be read.

    Returns
    -------
    bool

    Examples
    --------
    >>> import tempfile
    >>> d = Path(tempfile.mkdtemp())
    >>> is_done(LogTask(str(d / "r1.blf"), "r1.blf", "r1_blf-0", "v1", "r1", out=str(d)))
    False
    """
    out = Path(task.out)
    s = _part_dir(out, "summaries", task.vehicle) / f"{task.part}.parquet"
    e = _part_dir(out, "events", task.vehicle) / f"{task.part}.parquet"
    if not (s.exists() and e.exists()):
        return False
    if task.stats and not (_part_dir(out, "stats", task.vehicle) / f"{task.part}.parquet").exists():
        return False
    if retry_errors:
        import pyarrow.parquet as pq

        try:
            return pq.read_table(s, columns=["status"]).column("status")[0].as_py() == "ok"
        except Exception:  # an unreadable summary: redo the log
            return False
    return True

