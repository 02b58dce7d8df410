"""Vectorised CAN decoding: a frame table in, DBC signals out, per message id over all its frames.

Two halves, both exact replacements of the per-frame path (python-can's ``BLFReader`` yielding one
``can.Message`` per frame, then ``cantools`` ``Message.decode`` per frame):

* :func:`read_blf_table` reads a Vector BLF file into a frame table -- times, arbitration ids and
  a payload matrix (:class:`FramePayloads`) -- with numpy: the log containers are inflated as
  python-can inflates them, the object chain inside them is followed by pointer doubling over
  the ``LOBJ`` signatures, and the fields are gathered with fancy indexing. Times are
  ``ticks / 1e9`` (or ``/ 1e5``) plus the file's start time: a correctly rounded division by an
  exact power of ten, which is the value python-can's ``float(Decimal(ticks) * factor)`` gives,
  bit for bit. Anything unusual (a parse error, an unknown compression or header version, a
  CAN FD 64 object, an object smaller than its fields) returns ``None`` and the caller reads
  the file with python-can, so every corrupt-file error message stays as it was.
  :func:`read_blf_frames` is the on-demand form for the usual layout (48-byte CAN messages end
  to end, no remote frame): ids and the time-order check for every frame, read in place, and
  times and payloads only for the frames of the requested messages (:class:`BlfFrames`, equal
  to the same rows of the table).
* :func:`decode_message` decodes the requested signals of one DBC message from all its frames
  at once: each signal's bits are cut out of an 8-byte window of the payload matrix read as one
  little- or big-endian ``uint64`` (a shift and a mask), sign-extended, reinterpreted as IEEE
  floats where the DBC says so, and scaled with cantools' own arithmetic (integer scaling in
  integers, float scaling in floats), so the values equal cantools' bit for bit. A payload too
  short for a signal gives NaN for that signal and counts as undecodable (cantools'
  ``allow_truncated=True`` rule); bytes past the DBC length are ignored (``allow_excess``).
  Multiplexed and container messages, and signals this cannot cut exactly, go through the
  per-frame reference :func:`decode_message_reference` (cantools, one frame at a time).

Two inverses, for generated and fault-injected logs: :func:`set_signal` writes physical values of
one signal into the payloads (the DBC's scaling, rounded and clipped to the raw range; every
other bit kept), and :func:`write_blf_table` writes a frame table as a Vector BLF file that
python-can reads back frame for frame.

Equality with the per-frame path is tested on the real RAV4 log and on random payloads of a
generated DBC (``tests/test_decode.py``).
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Sequence
from pathlib import Path

import numpy as np

try:  # ISA-L's inflate: the same bytes as zlib's, about twice as fast (a dependency of asammdf)
    from isal import isal_zlib as _isal_zlib
except ImportError:  # pragma: no cover - isal comes with asammdf
    _isal_zlib = None
try:  # libdeflate's one-shot inflate into a buffer of the container's stated size: faster still
    import deflate as _libdeflate
except ImportError:  # pragma: no cover - a dependency of fdikit (and of asammdf)
    _libdeflate = None

__all__ = ["BlfFrames", "FramePayloads", "decode_message", "decode_message_reference", "read_blf_frames",
           "read_blf_table", "set_signal", "write_blf_table"]


# ---------------------------------------------------------------------------------- payload matrix
class FramePayloads(Sequence):
    """The payloads of N frames as one ``uint8`` matrix plus each frame's length.

    Behaves as a sequence of ``bytes`` (``payloads[k]`` is frame k's payload), so code written
    for a list of payloads keeps working; the decoder reads :attr:`matrix` directly.

    Parameters
    ----------
    matrix : ndarray of uint8, shape (N, W)
        Payload bytes, zero past each frame's length (W >= 8).
    lengths : ndarray of int, shape (N,)
        Payload length of each frame, bytes.

    Examples
    --------
    >>> p = FramePayloads.from_bytes([b"\\x01\\x02", b"", b"\\xff" * 8])
    >>> len(p), p[0], p[1], p.matrix.shape
    (3, b'\\x01\\x02', b'', (3, 8))
    """

    __slots__ = ("lengths", "matrix")

    def __init__(self, matrix: np.ndarray, lengths: np.ndarray):
        self.matrix = np.ascontiguousarray(matrix, dtype=np.uint8)
        self.lengths = np.asarray(lengths, dtype=np.int64)

    @classmethod
    def from_bytes(cls, data: Sequence[bytes]) -> FramePayloads:
        """Pack a sequence of payloads into a matrix (vectorised scatter of the joined bytes)."""
        if isinstance(data, FramePayloads):
            return data
        lengths = np.fromiter((len(d) for d in data), dtype=np.int64, count=len(data))
        width = max(8, int(lengths.max()) if lengths.size else 0)
        mat = np.zeros((lengths.size, width), np.uint8)
        if lengths.size and lengths.sum():
            flat = np.frombuffer(b"".join(bytes(d) for d in data), np.uint8)
            rows = np.repeat(np.arange(lengths.size), lengths)
            starts = np.cumsum(lengths) - lengths
            cols = np.arange(flat.size) - np.repeat(starts, lengths)
            mat[rows, cols] = flat
        return cls(mat, lengths)

    def __len__(self) -> int:
        return int(self.lengths.size)

    def __getitem__(self, k):
        if isinstance(k, int | np.integer):
            return self.matrix[k, :self.lengths[k]].tobytes()
        return self.take(np.arange(len(self))[k])

    def take(self, idx) -> FramePayloads:
        """The payloads of the frames ``idx`` (indices or a boolean mask)."""
        return FramePayloads(self.matrix[idx], self.lengths[idx])


# ---------------------------------------------------------------------------------- BLF frame table
_FILE_HEADER = struct.Struct("<4sLBBBBBBBBQQLL8H8H")  # python-can's FILE_HEADER_STRUCT
_OBJ_BASE = struct.Struct("<4sHHLL")                   # signature, header size, version, size, type
_CONTAINER = struct.Struct("<H6xL4x")                  # compression method, uncompressed size
_CAN_MESSAGE, _LOG_CONTAINER, _CAN_ERROR_EXT, _CAN_MESSAGE2 = 1, 10, 73, 86
_CAN_FD_MESSAGE, _CAN_FD_MESSAGE_64 = 100, 101
_BODY = {_CAN_MESSAGE: 16, _CAN_MESSAGE2: 16, _CAN_FD_MESSAGE: 84, _CAN_ERROR_EXT: 0}


def _u(buf: np.ndarray, pos: np.ndarray, dtype: str, n: int) -> np.ndarray:
    """Little-endian integers of ``n`` bytes at byte offsets ``pos`` of ``buf``."""
    idx = pos[:, None] + np.arange(n)
    return np.ascontiguousarray(buf[idx]).view(dtype).ravel()


def _object_chain(buf: np.ndarray) -> np.ndarray | None:
    """Start offsets of the objects python-can's ``_parse_data`` visits in ``buf`` (None: unusual)."""
    n = buf.size
    if n < 16:
        return np.zeros(0, np.int64) if n < 8 else None
    m = (buf[:-3] == 0x4C) & (buf[1:-2] == 0x4F) & (buf[2:-1] == 0x42) & (buf[3:] == 0x4A)  # b"LOBJ"
    cand = np.flatnonzero(m[: n - 15])  # a full base header must fit
    if cand.size == 0:
        return None
    size = _u(buf, cand + 8, "<u4", 4).astype(np.int64)
    nxt = cand + size
    # the next object: the first signature starting within [next_pos, next_pos + 4]
    j = np.searchsorted(cand, nxt)
    jj = np.minimum(j, cand.size - 1)
    found = (j < cand.size) & (cand[jj] <= nxt + 4)
    inside = nxt <= n
    sink = cand.size
    succ = np.where(found & inside, jj, sink)
    # not found although more than 8 bytes remain: python-can raises "Could not find next object"
    broken = inside & ~found & (nxt + 8 <= n)
    first = int(np.searchsorted(cand, 0))
    if cand[first] > 4 or (size < 16).any():
        return None
    succ = np.append(succ, sink)
    # nodes reachable from the first object (pointer doubling: within 2^k steps after k rounds)
    on = np.zeros(sink + 1, bool)
    on[first] = True
    jump = succ
    while True:
        reach = np.flatnonzero(on)
        new = jump[reach]
        if on[new].all():
            break
        on[new] = True
        jump = jump[jump]
    on = on[:sink]
    if (on & broken).any():
        return None
    keep = on & inside  # an object running past the end belongs to a tail that never completes
    return cand[keep]


_LOBJ = int.from_bytes(b"LOBJ", "little")
#: ``_LOW_BYTES[n]``: the mask of the first ``n`` bytes of a little-endian 8-byte word (n = 0 .. 8).
_LOW_BYTES = np.array([(1 << (8 * i)) - 1 for i in range(9)], dtype=np.uint64)

#: One CAN_MESSAGE / CAN_MESSAGE2 object with a version-1 header: python-can's structs laid end to end.
_CAN_V1 = np.dtype([("sig", "S4"), ("hsize", "<u2"), ("hver", "<u2"), ("size", "<u4"), ("type", "<u4"),
                    ("tflags", "<u4"), ("client", "<u2"), ("over", "<u2"), ("ticks", "<u8"),
                    ("chan", "<u2"), ("cflags", "u1"), ("dlc", "u1"), ("id", "<u4"), ("data", "u1", (8,))])
#: The first header word of a version-1 object with the header size masked out: b"LOBJ", version 1.
_SIG_VER_MASK, _SIG_VER1 = np.uint64(0xFFFF0000FFFFFFFF), np.uint64(_LOBJ | (1 << 48))
#: The second header word of a 48-byte CAN_MESSAGE / CAN_MESSAGE2 object (size, type).
_SIZE_TYPES = (np.uint64(_CAN_V1.itemsize | (_CAN_MESSAGE << 32)),
               np.uint64(_CAN_V1.itemsize | (_CAN_MESSAGE2 << 32)))


def _uniform_can(buf: np.ndarray) -> np.ndarray | None:
    """The objects as one structured view when they are all 48-byte classic CAN messages end to end
    (the usual BLF); None otherwise (the general chain walk then applies)."""
    n = buf.size // _CAN_V1.itemsize
    if n == 0:
        return None
    rec = buf[: n * _CAN_V1.itemsize].view(_CAN_V1)
    # the header as two little-endian words per object (one strided pass each, no string
    # comparison): b"LOBJ" and header version 1 (the header size bits masked out), then object
    # size 48 and type CAN_MESSAGE or CAN_MESSAGE2
    w = _words(buf, n)
    if not np.all((w[:, 0] & _SIG_VER_MASK) == _SIG_VER1):
        return None
    second = w[:, 1]
    first = second[0]
    if first not in _SIZE_TYPES or not np.all(second == first):  # one type (the usual log), else either
        if not np.all((second == _SIZE_TYPES[0]) | (second == _SIZE_TYPES[1])):
            return None
    rest = buf[n * _CAN_V1.itemsize:].tobytes()
    # what python-can does with the bytes after the last whole object: nothing, unless an object
    # starts there (then the general walk decides) or no signature is found with > 8 bytes left
    if rest.find(b"LOBJ", 0, 8) != -1 or len(rest) >= 8:
        return None
    return rec


def _words(buf: np.ndarray, n: int) -> np.ndarray:
    """The first ``n`` 48-byte objects of ``buf`` as little-endian 8-byte words, shape (n, 6)."""
    return buf[: n * _CAN_V1.itemsize].view("<u8").reshape(n, _CAN_V1.itemsize // 8)


def _inflate(body: bytes, size: int | None = None) -> bytes:
    """A zlib stream inflated as ``zlib.decompressobj().decompress`` inflates it (python-can's way).

    A complete stream has one inflation, so a faster inflater gives the same bytes: libdeflate
    (``deflate``) when the container states the inflated ``size`` and the stream fills exactly
    that, else ISA-L (``isal``, installed with asammdf) when it reads the stream to its end;
    anything else (neither installed, an error, a stream that stops early, a size that does not
    match) is inflated by zlib itself, so partial and failing streams behave exactly as before.
    """
    if _libdeflate is not None and size:
        try:
            return _libdeflate.zlib_decompress(body, size)
        except Exception:  # a wrong size, a truncated or corrupt stream: the paths below decide
            pass
    if _isal_zlib is not None:
        try:
            d = _isal_zlib.decompressobj()
            out = d.decompress(body)
            if d.eof:
                return out
        except Exception:  # isal's own error type: let zlib decide (and raise its zlib.error)
            pass
    return zlib.decompressobj().decompress(body)


def _tick_times(flags: np.ndarray, ticks: np.ndarray, start: float) -> np.ndarray:
    """Object times, s: ``ticks / 1e5`` (flag 1, 10 us ticks) or ``ticks / 1e9`` (ns), plus the start.

    ``ticks`` are below 2**53 (exact in float64; converted through int64, which gives the same
    floats as uint64 and is faster).
    """
    t = ticks.view(np.int64).astype(float) if ticks.dtype == np.uint64 else ticks.astype(float)
    ten_us = flags == 1
    if not ten_us.any():
        return t / 1e9 + start
    return np.where(ten_us, t / 1e5, t / 1e9) + start


def _inflated(path) -> tuple[np.ndarray, float, dict[str, int]] | None:
    """The object stream of a BLF file (log containers inflated and joined), its start time and
    header counts; ``None`` for anything unusual (python-can then reads the file)."""
    from can.io.blf import systemtime_to_timestamp

    raw = Path(path).read_bytes()
    try:
        hdr = _FILE_HEADER.unpack_from(raw)
    except struct.error:
        return None
    if hdr[0] != b"LOGG":
        return None
    start = systemtime_to_timestamp(hdr[14:22])
    pos, chunks = hdr[1], []
    while pos < len(raw):
        if pos + _OBJ_BASE.size > len(raw):
            return None
        sig, _, _, osize, otype = _OBJ_BASE.unpack_from(raw, pos)
        if sig != b"LOBJ" or osize < _OBJ_BASE.size or pos + osize > len(raw):
            return None
        if otype == _LOG_CONTAINER:
            if osize < _OBJ_BASE.size + _CONTAINER.size:
                return None
            method, usize = _CONTAINER.unpack_from(raw, pos + _OBJ_BASE.size)
            body = raw[pos + _OBJ_BASE.size + _CONTAINER.size: pos + osize]
            if method == 0:
                chunks.append(body)
            elif method == 2:
                try:
                    chunks.append(_inflate(body, usize))
                except zlib.error:
                    return None
            else:
                return None
        pos += osize + osize % 4
    buf = np.frombuffer(b"".join(chunks), np.uint8)
    return buf, start, {"file_size": int(hdr[10]), "object_count": int(hdr[12])}


class BlfFrames:
    """The frames of a BLF file of 48-byte classic CAN messages, read on demand (internal).

    What every frame needs (arbitration ids, the check that time never goes back) is read from
    the inflated objects in place; times and payloads only for the frames asked for
    (:meth:`times`, :meth:`payloads`), equal bit for bit to the same rows of
    :func:`read_blf_table`'s table. Built by :func:`read_blf_frames`.

    Attributes
    ----------
    n_frames : int
    header : dict
        ``file_size`` and ``object_count`` from the file header.
    """

    __slots__ = ("_flags", "_ordered", "_ticks", "_words", "header", "ids", "n_frames", "start")

    def __init__(self, buf: np.ndarray, rec: np.ndarray, start: float, header: dict[str, int]):
        self._words = _words(buf, rec.size)
        self.start = start
        self.header = header
        self.n_frames = int(rec.size)
        self._ticks = rec["ticks"]
        self._flags = rec["tflags"]
        tk = self._ticks
        self._ordered = not np.any(tk[1:] < tk[:-1])
        #: Arbitration ids (29-bit), uint32, shape (n_frames,).
        self.ids = rec["id"] & np.uint32(0x1FFFFFFF)

    def max_ticks(self) -> int:
        """The largest time stamp in ticks."""
        return int(self._ticks[-1] if self._ordered else self._ticks.max())

    def has_remote(self) -> bool:
        """Whether any frame is a remote frame (which the frame table leaves out)."""
        return bool(np.any(self._words[:, 4] & np.uint64(0x80 << 16)))

    def times_ordered(self) -> bool:
        """True when the frame times are finite and never decrease (told from the integer ticks:
        one tick unit and non-decreasing ticks give non-decreasing correctly rounded times);
        False when the ticks cannot tell (then check :meth:`times` itself)."""
        return (self._ordered and bool(np.isfinite(self.start))
                and bool(np.all(self._flags == self._flags[0])))

    def times(self, idx=None) -> np.ndarray:
        """Frame times, s (absolute, as python-can gives them), of the frames ``idx`` (default all)."""
        if idx is None:
            return _tick_times(self._flags, self._ticks, self.start)
        return _tick_times(self._flags[idx], self._ticks[idx], self.start)

    def select(self, frame_id: int) -> np.ndarray:
        """Indices of the frames with arbitration id ``frame_id``."""
        if not 0 <= frame_id <= 0x1FFFFFFF:
            return np.zeros(0, np.intp)
        return np.flatnonzero(self.ids == np.uint32(frame_id))

    def payloads(self, idx) -> FramePayloads:
        """The payloads of the frames ``idx`` (bytes past each frame's length cleared)."""
        ctl, data = self._words[idx, 4], self._words[idx, 5]  # channel, flags, dlc, id | the data bytes
        length = np.minimum((ctl >> np.uint64(24)) & np.uint64(0xFF), np.uint64(8)).astype(np.int64)
        if (length < 8).any():
            data = data & _LOW_BYTES[length]
        return FramePayloads(data.view(np.uint8).reshape(-1, 8), length)


def read_blf_frames(path) -> BlfFrames | None:
    """The frames of a BLF file as a :class:`BlfFrames`, or ``None`` when it is not the usual
    layout (every object a 48-byte CAN message, no remote frame, ticks below 2**53): then
    :func:`read_blf_table` (or python-can) reads it."""
    got = _inflated(path)
    if got is None:
        return None
    buf, start, header = got
    rec = _uniform_can(buf)  # the structured view of the objects, checked
    if rec is None:
        return None
    frames = BlfFrames(buf, rec, start, header)
    if frames.has_remote() or frames.max_ticks() >= 2**53:
        return None
    return frames


def read_blf_table(path) -> tuple[np.ndarray, np.ndarray, FramePayloads, dict[str, int]] | None:
    """The CAN data frames of a BLF file as a table, or ``None`` when python-can should read it.

    Parameters
    ----------
    path : path-like

    Returns
    -------
    ts : ndarray, shape (N,)
        Frame times, s (absolute, as python-can gives them).
    ids : ndarray of int64, shape (N,)
        Arbitration ids (29-bit).
    payloads : FramePayloads
    header : dict
        ``file_size`` and ``object_count`` from the file header.

    Error frames and remote frames are left out, as :func:`fdikit.io.can._read_frames` leaves
    them out.
    """
    got = _inflated(path)
    if got is None:
        return None
    buf, start, header = got
    rec = _uniform_can(buf)
    if rec is not None:
        ticks = rec["ticks"]
        if ticks.size and int(ticks.max()) >= 2**53:
            return None
        ts = _tick_times(rec["tflags"], ticks, start)
        keep = (rec["cflags"] & 0x80) == 0
        length = np.minimum(rec["dlc"], 8).astype(np.int64)
        # the 8 data bytes of every object as one little-endian word (bytes 40..47), the bytes past
        # the frame's length cleared
        data = _words(buf, rec.size)[:, 5]
        ids = rec["id"].astype(np.int64) & 0x1FFFFFFF
        if not keep.all():  # remote frames are not data
            ts, ids, length, data = ts[keep], ids[keep], length[keep], data[keep]
        data = data & _LOW_BYTES[length] if (length < 8).any() else data
        mat = np.ascontiguousarray(data, dtype="<u8").view(np.uint8).reshape(-1, 8)
        return ts, ids, FramePayloads(mat, length), header
    objs = _object_chain(buf)
    if objs is None:
        return None
    version = _u(buf, objs + 6, "<u2", 2)
    otype = _u(buf, objs + 12, "<u4", 4)
    if (otype == _CAN_FD_MESSAGE_64).any():
        return None
    # objects of another header version are skipped (python-can warns and skips them)
    frame = np.isin(otype, (_CAN_MESSAGE, _CAN_MESSAGE2, _CAN_FD_MESSAGE)) & ((version == 1) | (version == 2))
    objs, otype, version = objs[frame], otype[frame], version[frame]
    body = objs + np.where(version == 1, 32, 40)
    osize = _u(buf, objs + 8, "<u4", 4).astype(np.int64)
    need = (body - objs) + np.where(otype == _CAN_FD_MESSAGE, _BODY[_CAN_FD_MESSAGE], 16)
    if (osize < need).any():
        return None
    flags_t = _u(buf, objs + 16, "<u4", 4)
    ticks = _u(buf, objs + 24, "<u8", 8)
    if ticks.size and int(ticks.max()) >= 2**53:
        return None
    # python-can: float(Decimal(ticks) * factor) + start, factor 1e-5 when flags == 1 else 1e-9;
    # dividing an exact integer by an exact 1e5 / 1e9 rounds the same exact quotient correctly
    ts = _tick_times(flags_t, ticks, start)
    cflags = buf[body + 2]
    dlc = buf[body + 3].astype(np.int64)
    can_id = _u(buf, body + 4, "<u4", 4).astype(np.int64)
    fd = otype == _CAN_FD_MESSAGE
    length = np.where(fd, buf[np.where(fd, body + 14, body)].astype(np.int64), np.minimum(dlc, 8))
    data_at = np.where(fd, body + 20, body + 8)
    keep = (cflags & 0x80) == 0  # remote frames are not data
    width = 64 if fd.any() else 8
    cols = np.arange(width)
    mat = buf[np.minimum(data_at[keep, None] + cols, buf.size - 1)]
    mat = np.where(cols < length[keep, None], mat, 0).astype(np.uint8)
    return ts[keep], can_id[keep] & 0x1FFFFFFF, FramePayloads(mat, length[keep]), header


# ---------------------------------------------------------------------------------- signal decoding
def decode_message_reference(msg, snames: Sequence[str],
                             data: Sequence[bytes]) -> tuple[np.ndarray, np.ndarray]:
    """Per-frame cantools decoding (the reference): ``(values (n, k), n_undecodable (k,))``.

    A frame cantools cannot decode at all counts against every signal; a signal missing from a
    decoded frame (payload too short) counts against that signal. Values are NaN where missing.
    """
    cols = np.full((len(data), len(snames)), np.nan)
    n_bad = np.zeros(len(snames), int)
    decode = msg.decode
    for j in range(len(data)):
        try:
            dec = decode(bytes(data[j]), decode_choices=False, scaling=True, allow_truncated=True)
        except Exception:  # cantools raises several types for payloads it cannot decode
            n_bad += 1
            continue
        for c, s in enumerate(snames):
            x = dec.get(s)
            if x is None:
                n_bad[c] += 1
            else:
                cols[j, c] = float(x)
    return cols, n_bad


def _network_start(sig) -> int:
    """First bit of the signal in network (sequential) order, as cantools computes it."""
    if sig.byte_order == "little_endian":
        return int(sig.start)
    return 8 * (sig.start // 8) + (7 - sig.start % 8)


def _raw_bits(sig, mat: np.ndarray, words: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray | None:
    """Raw unsigned bits of ``sig`` from every payload row, uint64; None when not one 8-byte window.

    ``words``: the payloads (8 bytes, zero past each frame's length) read as one little- and one
    big-endian word per frame; the window of bytes ``b0 .. b0 + 7`` (zero past byte 7) is then a
    shift of them, with no copy of the matrix.
    """
    n = int(sig.length)
    if not 1 <= n <= 64:
        return None
    seq = _network_start(sig)
    b0 = seq // 8
    off = seq - 8 * b0
    mask = np.uint64((1 << n) - 1)
    if words is not None and b0 <= 7 and off + n <= 64:
        le, be = words
        if sig.byte_order == "little_endian":
            return (le >> np.uint64(8 * b0 + off)) & mask
        return ((be << np.uint64(8 * b0)) >> np.uint64(64 - off - n)) & mask
    if off + n > 64 or b0 + 8 > mat.shape[1]:
        return None
    window = np.ascontiguousarray(mat[:, b0:b0 + 8])
    if sig.byte_order == "little_endian":
        return (window.view("<u8").ravel() >> np.uint64(off)) & mask
    return (window.view(">u8").ravel().astype(np.uint64) >> np.uint64(64 - off - n)) & mask


def _scaled(sig, raw: np.ndarray) -> np.ndarray | None:
    """cantools' ``raw_to_scaled(raw, decode_choices=False)`` as float64, vectorised; None: unsupported."""
    from cantools.database.conversion import (
        IdentityConversion,
        LinearConversion,
        LinearIntegerConversion,
        NamedSignalConversion,
    )

    n = int(sig.length)
    conv = sig.conversion
    if isinstance(conv, NamedSignalConversion):
        conv = conv._conversion
    if conv.is_float:
        if n == 32:
            x = raw.astype(np.uint32).view(np.float32).astype(np.float64)
        elif n == 64:
            x = raw.view(np.float64)
        else:
            return None
    elif sig.is_signed:
        if n == 64:
            x = raw.view(np.int64)
        else:
            x = raw.astype(np.int64)
            x = np.where(x >= (1 << (n - 1)), x - (1 << n), x)
    else:
        x = raw
    if isinstance(conv, IdentityConversion):
        return x.astype(np.float64)
    if not isinstance(conv, LinearConversion | LinearIntegerConversion):
        return None
    scale, offset = conv.scale, conv.offset
    if conv.is_float or isinstance(scale, float):
        # Python: float(raw) * scale + offset (an int offset is promoted, as Python promotes it)
        return x.astype(np.float64) * float(scale) + float(offset)
    # integer scale: raw * scale is an exact Python int; in int64 when it cannot overflow
    if not isinstance(scale, int) or not isinstance(offset, int | float):
        return None
    bound = (1 << n) * abs(scale) + (abs(offset) if isinstance(offset, int) else 0)
    if bound >= 2**62:
        return None
    prod = x.astype(np.int64) * np.int64(scale)
    if isinstance(offset, int):
        return (prod + np.int64(offset)).astype(np.float64)
    return prod.astype(np.float64) + offset


def decode_message(msg, snames: Sequence[str], payloads: Sequence[bytes] | FramePayloads
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Decode signals ``snames`` of message ``msg`` from all its frames at once.

    Parameters
    ----------
    msg : cantools Message
    snames : sequence of str
        Signal names of ``msg``.
    payloads : FramePayloads or sequence of bytes, length n
        The frames of this message.

    Returns
    -------
    values : ndarray, shape (n, k)
        Physical values (``decode_choices=False``), NaN where a payload is too short for the
        signal.
    n_undecodable : ndarray of int, shape (k,)
        Frames too short for each signal (or undecodable).

    Examples
    --------
    >>> import cantools
    >>> db = cantools.database.load_string('''VERSION ""
    ... BO_ 180 SPEED: 8 XXX
    ...  SG_ SPEED : 47|16@0+ (0.01,0) [0|250] "km/h" XXX
    ... ''', database_format="dbc")
    >>> v, bad = decode_message(db.messages[0], ["SPEED"], [bytes([0, 0, 0, 0, 0, 3, 232, 0]), b"\\x00"])
    >>> v[:, 0].tolist(), bad.tolist()
    ([10.0, nan], [1])
    """
    pay = FramePayloads.from_bytes(payloads)
    if msg.is_multiplexed() or getattr(msg, "is_container", False) or not msg.length:
        return decode_message_reference(msg, snames, pay)
    sigs = [msg.get_signal_by_name(s) for s in snames]
    out = np.full((len(pay), len(sigs)), np.nan)
    n_bad = np.zeros(len(sigs), int)
    mat = pay.matrix
    words = None
    if mat.shape[1] == 8:  # classic CAN: every window of a signal in bytes 0..7 is a shift of these
        words = (mat.view("<u8").reshape(-1).astype(np.uint64, copy=False),
                 mat.view(">u8").reshape(-1).astype(np.uint64))
    bits = 8 * pay.lengths
    short_bits = int(bits.min()) if bits.size else 0
    for c, sig in enumerate(sigs):
        end = _network_start(sig) + int(sig.length)
        if end > 8 * msg.length:
            return decode_message_reference(msg, snames, pay)
        if (words is None or _network_start(sig) // 8 > 7) and mat.shape[1] < msg.length + 8:
            mat = np.pad(mat, ((0, 0), (0, msg.length + 8 - mat.shape[1])))
        raw = _raw_bits(sig, mat, words)
        with np.errstate(all="ignore"):  # NaN / inf IEEE patterns convert as Python converts them
            vals = None if raw is None else _scaled(sig, raw)
        if vals is None:
            return decode_message_reference(msg, snames, pay)
        if end <= short_bits:  # every payload holds the signal
            out[:, c] = vals
            continue
        ok = end <= bits  # cantools' allow_truncated rule; excess bytes are ignored
        out[ok, c] = vals[ok]
        n_bad[c] = int((~ok).sum())
    return out, n_bad


# ---------------------------------------------------------------------------------- writing
def set_signal(msg, name: str, payloads: Sequence[bytes] | FramePayloads, values) -> FramePayloads:
    """Payloads with signal ``name`` of ``msg`` set to the physical ``values`` (one per frame).

    The raw value is ``round((value - offset) / scale)`` clipped to the signal's bit range (float
    signals: the IEEE bits); every other bit of the payload is kept. Frames too short for the
    signal are left as they are.

    Examples
    --------
    >>> import cantools
    >>> db = cantools.database.load_string('''VERSION ""
    ... BO_ 180 SPEED: 8 XXX
    ...  SG_ SPEED : 47|16@0+ (0.01,0) [0|250] "km/h" XXX
    ... ''', database_format="dbc")
    >>> p = set_signal(db.messages[0], "SPEED", [bytes(8)], [12.34])
    >>> decode_message(db.messages[0], ["SPEED"], p)[0].round(6).tolist()
    [[12.34]]
    """
    from ..errors import DataError

    sig = msg.get_signal_by_name(name)
    pay = FramePayloads.from_bytes(payloads)
    n = int(sig.length)
    seq = _network_start(sig)
    b0, off = seq // 8, seq % 8
    if not 1 <= n <= 64 or off + n > 64:
        raise DataError(f"signal {msg.name}.{name} ({n} bits at bit {seq}) does not fit one 8-byte window")
    conv = sig.conversion
    conv = getattr(conv, "_conversion", conv)
    scale, offset = float(getattr(conv, "scale", 1)), float(getattr(conv, "offset", 0))
    v = np.broadcast_to(np.asarray(values, float), (len(pay),))
    x = (v - offset) / scale
    if conv.is_float:
        if n == 32:
            raw = x.astype(np.float32).view(np.uint32).astype(np.uint64)
        elif n == 64:
            raw = x.astype(np.float64).view(np.uint64)
        else:
            raise DataError(f"float signal {msg.name}.{name} has {n} bits; only 32 and 64 are written")
    else:
        lo, hi = (-(2 ** (n - 1)), 2 ** (n - 1) - 1) if sig.is_signed else (0, 2**n - 1)
        r = np.clip(np.rint(np.nan_to_num(x)), lo, hi)
        raw = r.astype(np.int64).view(np.uint64) if sig.is_signed else r.astype(np.uint64)
    mask = np.uint64((1 << n) - 1)
    raw = raw & mask
    mat = np.pad(pay.matrix, ((0, 0), (0, max(0, b0 + 8 - pay.matrix.shape[1]))))
    window = np.ascontiguousarray(mat[:, b0:b0 + 8])
    dt = "<u8" if sig.byte_order == "little_endian" else ">u8"
    shift = np.uint64(off if dt == "<u8" else 64 - off - n)
    w = window.view(dt).ravel().astype(np.uint64)
    w = (w & ~(mask << shift)) | (raw << shift)
    ok = seq + n <= 8 * pay.lengths
    new = w.astype(dt).view(np.uint8).reshape(-1, 8)
    window[ok] = new[ok]
    mat[:, b0:b0 + 8] = window
    return FramePayloads(mat[:, :pay.matrix.shape[1]], pay.lengths)


def write_blf_table(path, ts, ids, payloads: Sequence[bytes] | FramePayloads, *, channel: int = 1,
                    container_bytes: int = 128 * 1024) -> Path:
    """Write classic CAN frames as a Vector BLF file (zlib log containers of CAN_MESSAGE objects).

    Parameters
    ----------
    path : path-like
    ts : ndarray, shape (N,)
        Absolute frame times, s (non-decreasing); stored in nanoseconds from the file's start time
        (the first frame's time to the millisecond, as BLF headers keep it).
    ids : ndarray of int, shape (N,)
        Arbitration ids (above 0x7FF: extended ids).
    payloads : FramePayloads or sequence of bytes
        At most 8 bytes each.
    channel : int
        Bus number written in every frame (1-based, as BLF counts).
    container_bytes : int
        Uncompressed bytes per log container.

    Returns
    -------
    Path
    """
    from can.io.blf import systemtime_to_timestamp, timestamp_to_systemtime

    pay = FramePayloads.from_bytes(payloads)
    ts = np.asarray(ts, float)
    ids = np.asarray(ids, np.int64)
    n = ts.size
    start_st = timestamp_to_systemtime(float(ts[0])) if n else (0,) * 8
    start = systemtime_to_timestamp(start_st)
    rec = np.zeros(n, _CAN_V1)
    rec["sig"], rec["hsize"], rec["hver"], rec["size"] = b"LOBJ", 32, 1, _CAN_V1.itemsize
    rec["type"], rec["tflags"], rec["chan"] = _CAN_MESSAGE, 2, channel
    rec["ticks"] = np.rint((ts - start) * 1e9).astype(np.uint64)
    rec["dlc"] = np.minimum(pay.lengths, 8)
    rec["id"] = np.where(ids > 0x7FF, ids | 0x80000000, ids).astype(np.uint32)
    mat = pay.matrix if pay.matrix.shape[1] >= 8 else np.pad(pay.matrix, ((0, 0), (0, 8)))
    rec["data"] = mat[:, :8]
    raw = rec.tobytes()
    body = bytearray()
    for a in range(0, len(raw), container_bytes):
        piece = raw[a:a + container_bytes]
        z = zlib.compress(piece)
        size = _OBJ_BASE.size + _CONTAINER.size + len(z)
        body += _OBJ_BASE.pack(b"LOBJ", _OBJ_BASE.size, 1, size, _LOG_CONTAINER)
        body += _CONTAINER.pack(2, len(piece)) + z + bytes(size % 4)
    stop_st = timestamp_to_systemtime(float(ts[-1])) if n else (0,) * 8
    file_size = 144 + len(body)
    head = _FILE_HEADER.pack(b"LOGG", 144, 5, 0, 0, 0, 2, 6, 8, 1, file_size, 144 + len(raw), n, n,
                             *start_st, *stop_st)
    path = Path(path)
    path.write_bytes(head + bytes(144 - len(head)) + bytes(body))
    return path
