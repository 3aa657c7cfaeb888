"""Outline text built whole-array: the JSON and SVG rings of the writers, number by number
the same characters as Python's ``repr`` (JSON) and ``format(v, "g")`` (SVG) write.

The writers round every outline coordinate to ``digits`` decimals first (``np.round``),
so each value v is the double nearest K / 10^digits for a whole K.  Below 2^40 that
double's shortest repr is K / 10^digits itself, trailing zeros dropped (no other decimal
of as few digits is within half an ulp of it), so repr, and ``g`` below 10^(6 - digits),
are digits of K; above, ``g`` keeps 6 significant digits, rounding half to even on the
exact double, and a dropped tail of exactly 5, 50, ... is decided by the sign of
v·10^digits − K, computed exactly (Dekker's product).  Values outside the range where
this holds (or not finite) are left to Python's formatting (:func:`ring_texts` returns
None).
"""

from __future__ import annotations

import numpy as np

MAX_VALUE = 2.0**40  # |v| below this: the double nearest K / 10^digits has K's digits for repr
G_DIGITS = 6  # format(v, "g"): significant digits
_SPLIT = 134217729.0  # 2^27 + 1: Veltkamp's split of a double into two 26-bit halves
STYLES = ("json", "svg")


def _product_sign(v: np.ndarray, scale: float, whole: np.ndarray) -> np.ndarray:
    """sign(v·scale − whole) of the exact real product (v >= 0, scale a whole power of
    10 below 2^26, whole the nearest whole number to it): Dekker's two-product."""
    p = v * scale
    c = _SPLIT * v
    hi = c - (c - v)
    lo = v - hi
    err = (hi * scale - p) + lo * scale  # scale needs no split: it has under 27 bits
    return np.sign((p - whole) + err)


def _column_digits(values: np.ndarray, width: int, shown: np.ndarray) -> np.ndarray:
    """(N, width) ASCII digits of whole ``values`` >= 0, right-aligned, the leading
    ``width - shown`` columns 0 (no character)."""
    out = np.zeros((len(values), width), dtype=np.uint8)
    rest = values.copy()
    for col in range(width - 1, -1, -1):
        nxt = rest // 10
        out[:, col] = np.where(width - col <= shown, rest - 10 * nxt + 48, 0)
        rest = nxt
    return out


def _digit_count(values: np.ndarray) -> np.ndarray:
    """How many digits each whole number >= 0 has (1 for 0)."""
    count = np.ones(len(values), dtype=np.int64)
    top = int(values.max()) if len(values) else 0
    power = 10
    while power <= top:
        count += values >= power
        power *= 10
    return count


def decimal_fields(values, digits: int, style: str) -> np.ndarray | None:
    """The text of each of ``values`` (already rounded to ``digits`` decimals) as
    ``repr`` writes it (style "json") or ``format(v, "g")`` (style "svg"), as one row of
    characters per value: ASCII codes, padded anywhere with 0 (no character), so that
    dropping the zeros of a row leaves its text.

    Parameters
    ----------
    values : (N,) float array
        Numbers rounded by ``np.round(x, digits)``.
    digits : int
        Their decimals, 0 to 6.
    style : str
        "json" or "svg".

    Returns
    -------
    (N, W) uint8 array or None
        None where some value is outside the range built exactly here (see the module's
        docstring): the caller formats those in Python.
    """
    if style not in STYLES:
        raise ValueError(f"style must be one of {STYLES}, got {style!r}")
    v = np.asarray(values, dtype=np.float64).reshape(-1)
    if not 0 <= digits <= 6 or not np.isfinite(v).all():
        return None
    mag = np.abs(v)
    if len(v) and (mag.max() >= MAX_VALUE or ((mag > 0) & (mag < 1e-4)).any()):
        return None  # beyond the exact range, or an exponent (both write 1e-05)
    scale = 10**digits
    whole = np.rint(mag * scale)
    k = whole.astype(np.int64)
    if not np.array_equal(k / scale if digits else whole, mag):
        return None  # not rounded to these decimals
    decimals = np.full(len(v), digits, dtype=np.int64)
    if style == "svg" and digits:
        # g keeps G_DIGITS significant digits (a leading "0." counts for none): a value of
        # D whole digits keeps G_DIGITS - D decimals, rounded half to even on the exact double
        significant = np.where(k >= scale, _digit_count(k // scale), 0) + digits
        drop = np.clip(significant - G_DIGITS, 0, digits)
        if drop.any():
            unit = 10**drop
            q = k // unit
            r = k - q * unit
            half = unit // 2
            up = r > half
            tie = np.flatnonzero((r == half) & (drop > 0))
            if len(tie):
                sign = _product_sign(mag[tie], float(scale), whole[tie])
                up[tie] = (sign > 0) | ((sign == 0) & (q[tie] % 2 == 1))
            k = q + up
            decimals = digits - drop
    unit = 10**decimals
    int_part = k // unit
    rest = k - int_part * unit
    if style == "svg" and len(v) and int_part.max() >= 10**G_DIGITS:
        return None  # g writes an exponent
    # trailing zeros of the decimals are not written; repr keeps one ("12.0"), g none ("12")
    shown = decimals.copy()
    for _ in range(digits):
        zero = (shown > 0) & (rest % 10 == 0)
        shown -= zero
        rest = np.where(zero, rest // 10, rest)
    point = np.full(len(v), style == "json") | (shown > 0)
    if style == "json":
        shown = np.maximum(shown, 1)  # "12.0": rest is 0 there
    sign = np.where(np.signbit(v), np.uint8(ord("-")), np.uint8(0))
    width = int(_digit_count(int_part).max()) if len(v) else 1
    columns = [
        sign[:, None],
        _column_digits(int_part, width, _digit_count(int_part)),
        np.where(point, np.uint8(ord(".")), np.uint8(0))[:, None],
    ]
    if digits:
        # the decimals left-aligned: the first `shown` of `digits` columns
        frac = _column_digits(rest, digits, shown)  # right-aligned ...
        shift = digits - shown
        cols = np.arange(digits)[None, :] + shift[:, None]  # ... moved left by their padding
        columns.append(np.take_along_axis(frac, np.minimum(cols, digits - 1), axis=1))
        columns[-1][np.arange(digits)[None, :] >= shown[:, None]] = 0
    elif style == "json":
        columns.append(np.full((len(v), 1), ord("0"), dtype=np.uint8))
    return np.concatenate(columns, axis=1)


def ring_texts(xy: np.ndarray, count: np.ndarray, digits: int, style: str) -> list[str] | None:
    """Per ring (``count`` vertices each, ``xy`` (P, 2) one ring after another, rounded
    to ``digits`` decimals) its text: JSON ``[[x, y], [x, y], ...]`` or SVG path data
    ``Mx,y Lx,y x,y ...Z``; None where :func:`decimal_fields` builds no text.

    One row of characters per vertex (what comes before it, x, the separator, y, and
    after the ring's last vertex its end and a newline), padded with 0; the zeros of all
    rows dropped at once leave the rings, one per line."""
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    count = np.asarray(count, dtype=np.int64)
    if len(count) == 0:
        return []
    if (count < 2).any():
        return None  # a lone vertex's SVG ring is "Mx,y LZ": left to the templates
    x = decimal_fields(xy[:, 0], digits, style)
    y = decimal_fields(xy[:, 1], digits, style)
    if x is None or y is None:
        return None
    begin = np.cumsum(count) - count
    kind = np.full(len(xy), 2)  # the ring's first vertex (0), second (1), any other (2)
    kind[begin] = 0
    kind[begin + 1] = np.minimum(kind[begin + 1], 1)
    last = np.zeros(len(xy), dtype=bool)
    last[np.cumsum(count) - 1] = True
    if style == "json":
        leads, sep, tail, close = (b"[[", b", [", b", ["), b", ", b"]", b"]\n"
    else:
        leads, sep, tail, close = (b"M", b" L", b" "), b",", b"", b"Z\n"
    table = np.zeros((3, 3), dtype=np.uint8)
    for row, text in enumerate(leads):
        table[row, : len(text)] = np.frombuffer(text, dtype=np.uint8)
    end = np.zeros((len(xy), 2), dtype=np.uint8)
    end[last] = np.frombuffer(close, dtype=np.uint8)
    parts = [table[kind], x, np.frombuffer(sep, np.uint8)[None, :].repeat(len(xy), 0), y]
    if tail:
        parts.append(np.frombuffer(tail, np.uint8)[None, :].repeat(len(xy), 0))
    chars = np.concatenate([*parts, end], axis=1).ravel()
    return chars[chars != 0].tobytes().decode("ascii").split("\n")[:-1]


__all__ = ["MAX_VALUE", "G_DIGITS", "STYLES", "decimal_fields", "ring_texts"]
