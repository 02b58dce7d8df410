"""The Vector BLF reader (frames read on demand when the file has the usual layout)."""

from __future__ import annotations

from ...errors import DataError
from ..can import _read_blf_frames, _read_frame_table
from .checks import _check_file
from .frames import _blf_to_signals, frames_to_signals
from .grid import _COMMON_OPTIONS, LoadedSignals, SourceReport


def read_blf(path, dbc, signals, rate=None, **kw) -> LoadedSignals:
    """Read a Vector BLF log with the bad-input policy of :mod:`fdikit.io.formats`.

    The frames come from the BLF reader of :func:`fdikit.io.read_can_log` (header size and
    object count checked, so truncation is an error); any other failure of the decompressor
    (a corrupt zlib container) is a :class:`~fdikit.errors.DataError` too. A file of the usual
    layout is read on demand (:func:`fdikit.io.decode.read_blf_frames`: times and payloads of
    the requested messages only), with the same checks, errors and numbers as
    :func:`frames_to_signals` on the whole frame table.

    Examples
    --------
    >>> s = read_blf("drive.blf", "toyota_rav4.dbc", ["SPEED.SPEED"], rate=50)  # doctest: +SKIP
    """
    p = _check_file(path, "BLF file")
    frames = None
    try:
        if set(kw) <= {*_COMMON_OPTIONS, "plausibility"}:  # the usual layout is read on demand
            frames = _read_blf_frames(p)
        if frames is None:
            ts, ids, data = _read_frame_table(p)
    except DataError:
        raise
    except Exception as exc:  # zlib.error and friends from a corrupt container
        raise DataError(f"BLF file {p.name!r} is corrupt ({type(exc).__name__}: {exc})") from None
    where = f"BLF file {p.name!r}"
    if frames is not None:
        src = SourceReport("blf", str(p), frames.n_frames)
        return _blf_to_signals(frames, dbc, signals, rate, source=src, where=where, **kw)
    src = SourceReport("blf", str(p), int(ts.size))
    return frames_to_signals(ts, ids, data, dbc, signals, rate, source=src, where=where, **kw)
