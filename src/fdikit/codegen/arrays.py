"""Constant C arrays of exact values (:func:`c_array`): the tables a generated monitor carries as
code bytes (density tables, filter matrices). Doubles parse back to exactly the same value: short
arrays as shortest round-trip decimals (readable), large ones as C99 hexadecimal floats
(:func:`hex_literals`, the text of :meth:`float.hex` formatted for all values at once: a table of
millions of values in a fraction of a second)."""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from ..errors import DataError
from .stages import lit

__all__ = ["HEX_FROM", "c_array", "forget_tables", "hex_literals"]

#: A double array of at least this many values is written as hexadecimal floats (:func:`c_array`).
HEX_FROM = 4096

#: the two hexadecimal digits of each byte value, as one uint16 of two ASCII bytes
_HEX2 = np.frombuffer(b"".join(b"%02x" % i for i in range(256)), np.uint16)
_DEC = np.frombuffer(b"0123456789", np.uint8)
# one literal's columns: sign, "0x", leading digit, ".", 13 mantissa digits, "p", exponent sign,
# 4 exponent digits, then the separator (2 columns)
_W = 1 + 2 + 1 + 1 + 13 + 1 + 1 + 4 + 2


def hex_literals(values, per_line: int = 8) -> str:
    """The finite doubles ``values`` as C99 hexadecimal floating constants, each the text of
    :meth:`float.hex` (``0x1.8000000000000p+1``, ``-0x0.0p+0``, subnormals as ``0x0.…p-1022``),
    joined by ``", "``, ``per_line`` to a line (``",\\n"`` between lines).

    A C compiler reads each back to exactly the same double (C99 6.4.4.2: a hexadecimal constant
    that fits the type is exact), and formatting is vectorised (no Python call per value).

    Parameters
    ----------
    values : array_like of float
        Any shape (flattened in C order); every value finite.
    per_line : int
        Literals per line.

    Returns
    -------
    str
        The literals and their separators, without a trailing separator (``""`` for no values).

    Raises
    ------
    DataError
        A value is not finite (no C literal of NaN or infinity is a constant), named by its index.

    Examples
    --------
    >>> hex_literals([3.0, -0.0, 0.1], per_line=2)
    '0x1.8000000000000p+1, -0x0.0p+0,\\n0x1.999999999999ap-4'
    """
    v = np.ascontiguousarray(np.asarray(values, dtype=np.float64).ravel())
    bad = np.flatnonzero(~np.isfinite(v))
    if bad.size:
        raise DataError(f"hex_literals: value {v[bad[0]]} at index {int(bad[0])} is not finite "
                        f"({bad.size} such values)")
    n = v.size
    if n == 0:
        return ""
    bits = v.view(np.uint64)
    neg = (bits >> np.uint64(63)).astype(bool)
    biased = ((bits >> np.uint64(52)) & np.uint64(0x7FF)).astype(np.int64)
    mant = bits & np.uint64((1 << 52) - 1)
    # the 16 hexadecimal digits of the bits, most significant first (the last 13: the mantissa)
    digits = _HEX2[bits.astype(">u8").view(np.uint8).reshape(n, 8)]
    zero = (biased == 0) & (mant == 0)
    exp = np.where(biased == 0, np.where(zero, 0, -1022), biased - 1023)
    a = np.abs(exp)
    buf = np.empty((n, _W), np.uint8)
    keep = np.ones((n, _W), bool)
    buf[:, 0] = ord("-")
    keep[:, 0] = neg
    buf[:, 1], buf[:, 2] = ord("0"), ord("x")
    buf[:, 3] = np.where(biased == 0, ord("0"), ord("1"))
    buf[:, 4] = ord(".")
    buf[:, 5:18] = np.ascontiguousarray(digits).view(np.uint8).reshape(n, 16)[:, 3:]
    keep[:, 6:18] = ~zero[:, None]                   # zero: "0x0.0p+0" (float.hex keeps one digit)
    buf[:, 18] = ord("p")
    buf[:, 19] = np.where(exp < 0, ord("-"), ord("+"))
    ndig = 1 + (a >= 10) + (a >= 100) + (a >= 1000)
    for k, div in enumerate((1000, 100, 10, 1)):     # the exponent in decimal, without leading zeros
        buf[:, 20 + k] = _DEC[(a // div) % 10]
        keep[:, 20 + k] = 4 - k <= ndig
    buf[:, 24] = ord(",")
    line_end = (np.arange(1, n + 1) % per_line) == 0
    buf[:, 25] = np.where(line_end, ord("\n"), ord(" "))
    keep[-1, 24:] = False                            # no separator after the last literal
    return buf[keep].tobytes().decode("ascii")


@lru_cache(maxsize=1)
def _hex_body(data: bytes) -> str:
    """:func:`hex_literals` of the doubles in ``data``, remembered for the next call with the same
    bytes (the double and float32 variants of a monitor carry the same tables)."""
    return hex_literals(np.frombuffer(data, np.float64))


def forget_tables() -> None:
    """Drop the remembered text of the last large table (:func:`c_array`): a generation ends with
    it, so that the next one formats its tables afresh and no table text stays in memory."""
    _hex_body.cache_clear()


def c_array(name: str, values: np.ndarray, ctype: str = "double") -> str:
    """A ``static const`` C array of ``values``, eight to a line (the text of a large table is
    remembered for the next call with the same values, until :func:`forget_tables`).

    Parameters
    ----------
    name : str
        The C name.
    values : array_like
        Flattened in C order; an empty array is written as one ``0``.
    ctype : str
        ``"double"``, or an integer type (the values written as integers).

    Returns
    -------
    str
        The definition. Doubles parse back exactly: finite arrays of at least :data:`HEX_FROM`
        values as hexadecimal floats (:func:`hex_literals`), others as shortest round-trip
        decimals (:func:`~fdikit.codegen.stages.lit`; ``NAN``, ``HUGE_VAL``).
    """
    v = np.asarray(values).ravel()
    if ctype == "double" and v.size >= HEX_FROM and np.isfinite(v).all():
        body = _hex_body(v.astype(np.float64).tobytes())
    else:
        if ctype != "double":
            items = [str(int(a)) for a in v.tolist()]
        elif np.isfinite(v).all():
            items = list(map(repr, v.astype(float).tolist()))
        else:
            items = [lit(a) for a in v]
        body = ",\n".join(", ".join(items[i:i + 8]) for i in range(0, len(items), 8))
    return f"static const {ctype} {name}[{max(v.size, 1)}] = {{\n{body or '0'}\n}};"
