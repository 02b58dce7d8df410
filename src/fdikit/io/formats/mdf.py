"""The MDF4 reader: decoded signal channels, or raw CAN frames (bus logging) decoded with a DBC."""

from __future__ import annotations

import difflib
import gc
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

from ...errors import DataError
from ..can import _load_dbc, _resolve
from .checks import _check_file, _check_signal_list
from .grid import LoadedSignals, SourceReport, series_to_grid


def _quiet_half_built(hook):
    """``sys.unraisablehook`` that drops the error of an asammdf destructor (``MDF4.__del__`` of an
    object whose constructor failed on a corrupt file has no ``_file`` to close and prints
    "Exception ignored ..." after our clear error); everything else goes to ``hook``."""

    def quiet(unraisable):
        obj = unraisable.object
        if str(getattr(obj, "__module__", "") or "").startswith("asammdf") and \
                getattr(obj, "__name__", "") == "__del__":
            return
        hook(unraisable)

    return quiet


def _drop_frames(exc: BaseException) -> None:
    """Release the frames (and the half-built objects in them) that an exception chain holds."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        seen.add(id(exc))
        exc.__traceback__ = None
        exc = exc.__context__ or exc.__cause__


def _open_mdf(p: Path, where: str):
    import logging

    from asammdf import MDF

    class _Collect(logging.Handler):
        def __init__(self):
            super().__init__(logging.WARNING)
            self.records: list[str] = []

        def emit(self, record):
            self.records.append(record.getMessage())

    h = _Collect()
    log = logging.getLogger("asammdf")
    log.addHandler(h)
    hook = sys.unraisablehook
    sys.unraisablehook = _quiet_half_built(hook)
    try:
        mdf = MDF(str(p))
        # touch every group's record layout now, so that a corrupt block fails here
        for i, g in enumerate(mdf.groups):
            _ = g.channel_group.cycles_nr, [c.name for c in g.channels], i
    except Exception as exc:  # asammdf raises many types for a corrupt or truncated file
        msg = f"{type(exc).__name__}: {str(exc)[:200]}"
        _drop_frames(exc)   # the half-built MDF object dies now, while its noise is filtered
        del exc
        gc.collect()
        raise DataError(f"{where} is not a readable MDF file (truncated or corrupt?): {msg}") from None
    finally:
        sys.unraisablehook = hook
        log.removeHandler(h)
    if h.records:
        mdf.close()
        raise DataError(f"{where} is damaged: asammdf reported {h.records[0][:200]!r}")
    return mdf


def _mdf_get(mdf, name: str, where: str, group=None, index=None):
    import logging

    try:
        prev = logging.getLogger("asammdf").level
        logging.getLogger("asammdf").setLevel(logging.ERROR)
        try:
            sig = mdf.get(name, group, index, raw=False, ignore_invalidation_bits=True)
        finally:
            logging.getLogger("asammdf").setLevel(prev)
    except Exception as exc:
        raise DataError(f"{where}: channel {name!r} cannot be read (corrupt file?): "
                        f"{type(exc).__name__}: {str(exc)[:200]}") from None
    s = np.asarray(sig.samples)
    if s.dtype.names or s.ndim != 1 or s.dtype.kind not in "biuf":
        raise DataError(f"{where}: channel {name!r} is not a numeric signal "
                        f"(dtype {s.dtype}, shape {s.shape})")
    v = s.astype(float)
    t = np.asarray(sig.timestamps, float)
    if t.shape != v.shape:
        raise DataError(f"{where}: channel {name!r} has {t.size} time stamps for {v.size} samples")
    if sig.invalidation_bits is not None:
        inval = np.asarray(sig.invalidation_bits, bool)
        if inval.shape == v.shape:
            v = np.where(inval, np.nan, v)  # invalid in the file: a bad sample
    unit = sig.unit or ""
    return t, v, unit


def _mdf_raw_can_groups(mdf) -> list[int]:
    from asammdf.blocks import v4_constants as v4c

    out = []
    for i, g in enumerate(mdf.groups):
        flags = getattr(g.channel_group, "flags", 0)
        if flags & v4c.FLAG_CG_BUS_EVENT and any(c.name == "CAN_DataFrame" for c in g.channels):
            out.append(i)
    return out


def read_mdf(path, signals=None, rate=None, *, dbc=None, channel: int | None = None, **kw) -> LoadedSignals:
    """Read an MDF4 file: decoded signal channels, or raw CAN frames decoded with a DBC.

    * With ``dbc`` and bus-logging groups (``CAN_DataFrame`` channels) in the file, the frames
      are decoded by asammdf's ``extract_bus_logging`` and time 0 is the first frame.
    * Otherwise each requested name must be one channel of the file (its name or a display
      name such as ``"MESSAGE.SIGNAL"``), on the file's own time axis; invalidation bits become
      bad (flagged) samples.

    Parameters
    ----------
    path : path-like
    signals : sequence of str
        Channel names (``"MESSAGE.SIGNAL"`` for bus logging).
    rate : float, optional
        Grid rate (Hz).
    dbc : path-like or cantools Database, optional
        Needed for raw CAN frames.
    channel : int, optional
        Bus (``CAN_DataFrame.BusChannel``) to decode, when a message is on several buses.
    **kw
        ``units``, ``max_gap``, ``method``, ``span``, ``stuck_after`` (see :func:`series_to_grid`).

    Returns
    -------
    LoadedSignals

    Examples
    --------
    >>> s = read_mdf("bus.mf4", ["SPEED.SPEED"], rate=50, dbc="toyota_rav4.dbc")  # doctest: +SKIP
    """
    p = _check_file(path, "MDF file")
    where = f"MDF file {p.name!r}"
    signals = _check_signal_list(signals)
    mdf = _open_mdf(p, where)
    try:
        raw_groups = _mdf_raw_can_groups(mdf)
        if dbc is not None and raw_groups:
            return _read_mdf_bus(mdf, p, where, raw_groups, dbc, signals, rate, kw, channel)
        if channel is not None:
            hint = "pass dbc= to decode them" if raw_groups else "this file holds decoded channels"
            raise DataError(f"{where}: channel= selects a bus of raw CAN frames; {hint}")
        if raw_groups and not any(s in mdf.channels_db for s in signals):
            raise DataError(f"{where} holds raw CAN frames (bus logging); pass dbc= to decode {signals}")
        series, units_src = {}, {}
        n_rec = 0
        for s in signals:
            if s not in mdf.channels_db:
                close = difflib.get_close_matches(s, list(mdf.channels_db), n=3)
                raise DataError(f"{where} has no channel {s!r}"
                                + (f"; did you mean {close}?" if close else ""))
            occ = mdf.channels_db[s]
            if len(occ) > 1:
                raise DataError(f"{where}: channel name {s!r} is ambiguous, it occurs in groups "
                                f"{sorted({g for g, _ in occ})}")
            g, i = occ[0]
            t, v, unit = _mdf_get(mdf, s, where, g, i)
            series[s] = (t, v)
            units_src[s] = unit
            n_rec += t.size
        src = SourceReport("mdf", str(p), n_rec)
        return series_to_grid(series, units_src, rate, source=src, where=where, **kw)
    finally:
        mdf.close()


def _read_mdf_bus(mdf, p, where, raw_groups, dbc, signals, rate, kw, channel=None) -> LoadedSignals:
    import logging

    db = _load_dbc(dbc)
    resolved = _resolve(db, signals)  # clear errors (and close matches) before the extraction
    t_first, t_last, n_frames = np.inf, -np.inf, 0
    f_t, f_id, f_len, f_bus = [], [], [], []
    for g in raw_groups:
        try:
            tm = np.asarray(mdf.get_master(g), float)
            fid = np.asarray(_mdf_get(mdf, "CAN_DataFrame.ID", where, g)[1], np.int64) & 0x1FFFFFFF
            fbus = np.asarray(_mdf_get(mdf, "CAN_DataFrame.BusChannel", where, g)[1], np.int64)
            names = [c.name for c in mdf.groups[g].channels]
            if "CAN_DataFrame.DataLength" in names:
                flen = np.asarray(_mdf_get(mdf, "CAN_DataFrame.DataLength", where, g)[1], np.int64)
            else:
                flen = np.asarray(_mdf_get(mdf, "CAN_DataFrame.DLC", where, g)[1], np.int64)
                fd = np.array([12, 16, 20, 24, 32, 48, 64])
                flen = np.where(flen <= 8, flen, fd[np.clip(flen - 9, 0, 6)])
        except DataError:
            raise
        except Exception as exc:
            raise DataError(f"{where}: the frames of CAN group {g} cannot be read: "
                            f"{type(exc).__name__}: {exc}") from None
        if not (tm.size == fid.size == flen.size == fbus.size):
            raise DataError(f"{where}: CAN group {g} has {tm.size} time stamps, {fid.size} ids and "
                            f"{flen.size} lengths")
        f_t.append(tm)
        f_id.append(fid)
        f_len.append(flen)
        f_bus.append(fbus)
        if tm.size:
            if not np.isfinite(tm).all():
                raise DataError(f"{where}: CAN group {g} has a non-finite time stamp at frame "
                                f"{int(np.flatnonzero(~np.isfinite(tm))[0])}")
            back = np.flatnonzero(np.diff(tm) < 0)
            if back.size:
                k = int(back[0]) + 1
                raise DataError(f"{where}: time of CAN group {g} goes backwards at frame {k} "
                                f"({float(tm[k - 1])!r} s then {float(tm[k])!r} s)")
            t_first, t_last = min(t_first, tm[0]), max(t_last, tm[-1])
            n_frames += tm.size
    if n_frames == 0:
        raise DataError(f"{where} holds no CAN frames")
    with tempfile.TemporaryDirectory() as tmp:
        if isinstance(dbc, str | os.PathLike):
            dbc_path = str(dbc)
        else:
            dbc_path = os.path.join(tmp, "db.dbc")
            Path(dbc_path).write_text(db.as_dbc_string())
        prev = logging.getLogger("asammdf").level
        logging.getLogger("asammdf").setLevel(logging.ERROR)
        try:
            out = mdf.extract_bus_logging({"CAN": [(dbc_path, int(channel or 0))]})
        except Exception as exc:
            raise DataError(f"{where}: the CAN frames cannot be decoded with {Path(dbc_path).name!r}: "
                            f"{type(exc).__name__}: {str(exc)[:200]}") from None
        finally:
            logging.getLogger("asammdf").setLevel(prev)
    try:
        series, units_src = {}, {}
        for s in signals:
            if s not in out.channels_db:
                raise DataError(f"{where} has no frame of message {s.split('.')[0]!r} needed for {s!r} "
                                "(or none that the DBC decodes)")
            if len(out.channels_db[s]) > 1:
                raise DataError(f"{where}: {s!r} is on more than one CAN bus; pass channel= to choose one")
            g, i = out.channels_db[s][0]
            t, v, unit = _mdf_get(out, s, where, g, i)
            series[s] = (t - t_first, v)
            units_src[s] = unit
    finally:
        out.close()
    # asammdf decodes the 8 stored data bytes whatever DataLength says, and skips frames silently
    # if it must: check it decoded every frame of the message, and make a frame too short for
    # the signal a bad sample (as frames_to_signals does)
    f_t, f_id, f_len = np.concatenate(f_t), np.concatenate(f_id), np.concatenate(f_len)
    if channel:
        on_bus = np.concatenate(f_bus) == int(channel)
        f_t, f_id, f_len = f_t[on_bus], f_id[on_bus], f_len[on_bus]
    counts = {}
    for full, msg, sig in resolved:
        m = f_id == msg.frame_id
        t, v = series[full]
        if m.sum() != t.size or not np.array_equal(f_t[m] - t_first, t):
            raise DataError(f"{where}: asammdf decoded {t.size} frames of message {msg.name!r} "
                            f"(id 0x{msg.frame_id:x}) but the file holds {int(m.sum())}")
        short = f_len[m] < _bytes_needed(msg, sig.name)
        if short.any():
            v = v.copy()
            v[short] = np.nan
            series[full] = (t, v)
        counts[full] = {"n_undecodable": int(short.sum())}
    src = SourceReport("mdf", str(p), int(n_frames))
    return series_to_grid(series, units_src, rate, source=src, where=where, counts=counts,
                          log_span=(0.0, float(t_last - t_first)), **kw)


def _bytes_needed(msg, signal: str) -> int:
    """Fewest payload bytes from which cantools decodes ``signal`` of ``msg``."""
    for n in range(0, max(msg.length, 1) + 1):
        try:
            if signal in msg.decode(bytes(n), decode_choices=False, allow_truncated=True):
                return n
        except Exception:  # a payload this short cannot be decoded at all
            continue
    return msg.length
