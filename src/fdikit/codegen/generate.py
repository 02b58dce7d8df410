"""Generating C from a monitor config: the artifacts' digest (the design hash compiled into the
code) and :func:`generate`, which writes the double and float32 variants and their layout."""

from __future__ import annotations

import hashlib
import json
import time
from pathlib import Path
from typing import Any

from ..errors import DataError
from .arrays import forget_tables
from .emit import GeneratedSource, emit_monitor, stage_digest

__all__ = ["config_digest", "generate", "generate_monitor"]


def config_digest(cfg: Any) -> str:
    """SHA-256 of what a config's monitor is made of: the bytes of every artifact it names
    (manifest and arrays), its ``[decision]`` table and its runtime options. A design changed
    after generation (``fdikit design`` rerun with other parameters, an artifact edited) changes it.
    """
    h = hashlib.sha256()
    for a in (*cfg.generators, *cfg.processors):
        for ext in (".json", ".npz"):
            f = cfg.artifacts / f"{a}{ext}"
            if f.exists():
                h.update(f"\0{a}{ext}\0".encode())
                h.update(f.read_bytes())
    h.update(json.dumps([cfg.decision, cfg.runtime, cfg.on_invalid,
                         [[c.name, c.plausibility] for c in cfg.channels]],
                        sort_keys=True, default=str).encode())
    return h.hexdigest()


def generate_monitor(mon: Any, out_dir: str | Path, *, name: str = "fdk_monitor",
                     design_hash: str | None = None, precisions=("double", "float")) -> dict[str, Any]:
    """Write the C of a built :class:`~fdikit.monitor.Monitor` into ``out_dir``.

    For each precision: ``<name>.h`` / ``<name>.c`` (double) and ``<name>_f32.h`` / ``<name>_f32.c``
    (float32), and ``<name>.layout.json`` (channels, state layout, design hash) for the harness.

    Returns
    -------
    dict
        ``files`` (paths), ``layout`` (of the double variant), ``design_hash``, ``seconds`` (the
        generation time) and ``code_bytes`` (source size per variant).
    """
    t0 = time.perf_counter()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    digest = stage_digest(mon) if design_hash is None else design_hash
    files, sizes, layout = [], {}, None
    try:   # (the variants share their large tables' text: formatted once, forgotten at the end)
        for prec in precisions:
            nm = name if prec == "double" else f"{name}_f32"
            src: GeneratedSource = emit_monitor(mon, name=nm, precision=prec, design_hash=digest)
            for fn, text in ((f"{nm}.h", src.header), (f"{nm}.c", src.source)):
                (out / fn).write_text(text)
                files.append(str(out / fn))
            sizes[prec] = len(src.header) + len(src.source)
            layout = layout or src.layout
            (out / f"{nm}.layout.json").write_text(json.dumps(src.layout, indent=1))
            files.append(str(out / f"{nm}.layout.json"))
    finally:
        forget_tables()
    return {"files": files, "layout": layout, "design_hash": digest, "code_bytes": sizes,
            "seconds": time.perf_counter() - t0}


def generate(config: str | Path, out_dir: str | Path, *, name: str | None = None,
             precisions=("double", "float"), stop_after: str | None = None) -> dict[str, Any]:
    """Generate C99 for the monitor a config describes, from its designed artifacts.

    Parameters
    ----------
    config : path
        A monitor config (:func:`fdikit.monitor.config.load_config`); ``fdikit design`` must have
        built its artifacts.
    out_dir : path
        Where the header, source and layout go.
    name : str, optional
        C prefix (default: ``fdk_`` and the config's file stem parent, sanitised).
    stop_after : str, optional
        The artifact name of the last processor to generate (:func:`~fdikit.codegen.subset_monitor`):
        the later processors are left out and the decision keeps the alarm channels still produced
        (e.g. ``"peer_check"``: the RAV4 monitor without its fault-type classifier).
        The result's ``monitor`` is that monitor (what the C must equal); its design hash is that
        of the config and the cut (``sha256(config_digest + "\\0stop_after=" + artifact)``).

    Raises
    ------
    DataError
        A stage that cannot be generated, named; stale or missing artifacts.
    """
    from ..monitor.config import build_monitor, load_config

    cfg = load_config(config)
    mon = build_monitor(cfg)
    digest = config_digest(cfg)
    if stop_after is not None:
        from .subset import subset_monitor

        if stop_after not in cfg.processors:
            raise DataError(f"stop_after = {stop_after!r} is not a processor of {config}; processors: "
                            f"{cfg.processors}")
        n = cfg.processors.index(stop_after) + 1
        mon = subset_monitor(mon, n)
        digest = hashlib.sha256(f"{digest}\0stop_after={stop_after}".encode()).hexdigest()
    if name is None:
        stem = "".join(ch if ch.isalnum() else "_" for ch in Path(config).resolve().parent.name.lower())
        name = f"fdk_{stem or 'monitor'}"
    if not name.isidentifier():
        raise DataError(f"the C name prefix must be an identifier, got {name!r}")
    res = generate_monitor(mon, out_dir, name=name, design_hash=digest, precisions=precisions)
    res["name"] = name
    res["monitor"] = mon
    return res
