"""Compiled CSV engine: exact decimal ↔ float64 conversion over raw bytes (numba).

Reading (:func:`parse_block`): one pass over the bytes of whole lines; fields split on the separator, blank
and ``#`` lines skipped, CR before LF ignored, optional double quotes and spaces around a field ignored.
A token with at most 19 significant digits is converted in the kernel:

* Clinger's fast path — mantissa w ≤ 2^53 and |q| ≤ 22: ``w · 10^q`` (or ``w / 10^-q``) is one correctly
  rounded IEEE operation on two exact doubles, hence exact;
* otherwise the Eisel–Lemire algorithm (Lemire, "Number parsing at a gigabyte per second", 2021; Mushtak &
  Lemire, "Fast number parsing without fallback", 2023): w normalised, multiplied by a 128-bit truncated
  power of five, rounded to nearest-even — exact for every w < 2^64 without a fallback.

Tokens with more than 19 significant digits (rare) are handed back to Python's ``float()`` (also exact).
Result: every value is bit-identical to ``float(token)``. Empty field and ``nan`` = NaN; ``inf``/``infinity``
accepted. A row with the wrong number of fields or a token that is not a number is counted and skipped.

Writing (:func:`format_block`): for each finite value the 17-digit decimal D ≈ x·10^(16-E) is computed from a
128-bit product (error < 1 unit), then the shortest of the 15-, 16- and 17-digit roundings that parses back
(through the exact parser above) to the same double is written; 15 digits are always tried first, so values
with a short decimal form (sensor readings, ``0.01``) come out as short as ``repr`` writes them. NaN is an
empty field. Every written value round-trips bit-exactly.
"""

from __future__ import annotations

import math

import numpy as np
from numba import uint64 as _u64
from numba.cpython.unsafe.numbers import leading_zeros

from formats.jit.decorators import njit

from .jit import cache as kernel_cache  # noqa: F401  (compiled kernels cached per user, never in the package)

# -- tables -------------------------------------------------------------------------------------------------
_Q_MIN = -342  # smallest power of ten with a table entry
_Q_MAX = 308
_W_MIN = -350  # writer's range of 10^k (k = 16 - E, E in [-324, 308])
_W_MAX = 350


def _pow5_table() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """128-bit approximations T of 5^q, top bit set, as (hi, lo) uint64 and the exponent t: 5^q ≈ T·2^t.

    q ≥ 0: T = 5^q truncated to 128 bits. q < 0: T = floor(2^b / 5^-q) + 1 (then truncated), the rounding
    the Eisel–Lemire correctness argument assumes.
    """
    qs = range(_W_MIN, _W_MAX + 1)
    hi = np.empty(len(qs), np.uint64)
    lo = np.empty(len(qs), np.uint64)
    tt = np.empty(len(qs), np.int64)
    mask = (1 << 64) - 1
    for i, q in enumerate(qs):
        if q >= 0:
            p = 5**q
            n = p.bit_length()
            c = p << (128 - n) if n <= 128 else p >> (n - 128)
            t = n - 128
        else:
            p = 5**-q
            z = p.bit_length()
            if q >= -27:
                b = z + 127
                c = (1 << b) // p + 1
                t = -b
            else:
                b = 2 * z + 128
                c = (1 << b) // p + 1
                t = -b
                extra = max(0, c.bit_length() - 128)  # to 128 bits at once (a bit a step: 14 ms of every start)
                c >>= extra
                t += extra
        hi[i] = c >> 64
        lo[i] = c & mask
        tt[i] = t
    return hi, lo, tt


T_HI, T_LO, T_EXP = _pow5_table()
POW10 = np.array([10.0**i for i in range(23)])
POW2 = np.array([math.ldexp(1.0, k) for k in range(-1074, 972)])  # POW2[k + 1074] = 2^k, exact
P10F = np.array([float(f"1e{k}") for k in range(-307, 310)])  # P10F[k + 307] ≈ 10^k
DIGIT_PAIRS = np.frombuffer("".join(f"{i:02d}" for i in range(100)).encode(), np.uint8).copy()
POW10_INT = np.array([10**i for i in range(20)], dtype=np.uint64)

_U0 = np.uint64(0)
_U1 = np.uint64(1)
_U2 = np.uint64(2)
_U3 = np.uint64(3)
_U9 = np.uint64(9)
_U10 = np.uint64(10)
_U32 = np.uint64(32)
_U63 = np.uint64(63)
_U64 = np.uint64(64)
_M32 = np.uint64(0xFFFFFFFF)
_M9 = np.uint64(0x1FF)
_TWO52 = np.uint64(1 << 52)
_TWO53 = np.uint64(1 << 53)
_MAXU = np.uint64(0xFFFFFFFFFFFFFFFF)
_E16 = np.uint64(10**16)
_E17 = np.uint64(10**17)
_E15 = np.uint64(10**15)
_E8 = np.uint64(10**8)
_E6 = np.uint64(10**6)
_E4 = np.uint64(10**4)
_E9 = np.uint64(10**9)
_U5 = np.uint64(5)
_U50 = np.uint64(50)
_U100 = np.uint64(100)
_U52 = np.uint64(52)
_M11 = np.uint64(0x7FF)
_MANT = np.uint64((1 << 52) - 1)
_ABS = np.uint64((1 << 63) - 1)
_S2 = np.uint64(2)
_S4 = np.uint64(4)
_S8 = np.uint64(8)
_S16 = np.uint64(16)
_S32 = np.uint64(32)
_S48 = np.uint64(48)
_S56 = np.uint64(56)
_S60 = np.uint64(60)
_S62 = np.uint64(62)


@njit(no_cpython_wrapper=True)  # only the blocks' kernels call it
def _mul128(a: np.uint64, b: np.uint64) -> tuple[np.uint64, np.uint64]:
    """Full 64×64 → 128-bit product (hi, lo)."""
    a0 = a & _M32
    a1 = a >> _U32
    b0 = b & _M32
    b1 = b >> _U32
    p00 = a0 * b0
    p01 = a0 * b1
    p10 = a1 * b0
    p11 = a1 * b1
    mid = (p00 >> _U32) + (p01 & _M32) + (p10 & _M32)
    lo = (mid << _U32) | (p00 & _M32)
    hi = p11 + (p01 >> _U32) + (p10 >> _U32) + (mid >> _U32)
    return hi, lo


@njit(no_cpython_wrapper=True)  # only the blocks' kernels call it
def decimal_to_double(w: np.uint64, q: int) -> float:
    """The double nearest to w·10^q (ties to even), w < 2^64; exact (Clinger fast path, else Eisel–Lemire)."""
    if w == _U0:
        return 0.0
    if w <= _TWO53 and -22 <= q <= 22:
        if q >= 0:
            return float(w) * POW10[q]
        return float(w) / POW10[-q]
    if q < _Q_MIN:
        return 0.0
    if q > _Q_MAX:
        return math.inf
    # normalise w (its leading zeros: one instruction)
    lz = int(leading_zeros(w))
    w <<= _u64(lz)
    i = q - _W_MIN
    # 64x64 -> 128-bit products, written out (numba calls in this hot path cost more than the work)
    b = T_HI[i]
    a0 = w & _M32
    a1 = w >> _U32
    b0 = b & _M32
    b1 = b >> _U32
    p00 = a0 * b0
    p01 = a0 * b1
    p10 = a1 * b0
    mid = (p00 >> _U32) + (p01 & _M32) + (p10 & _M32)
    lo = (mid << _U32) | (p00 & _M32)
    hi = a1 * b1 + (p01 >> _U32) + (p10 >> _U32) + (mid >> _U32)
    if (hi & _M9) == _M9:
        b = T_LO[i]
        b0 = b & _M32
        b1 = b >> _U32
        p00 = a0 * b0
        p01 = a0 * b1
        p10 = a1 * b0
        mid = (p00 >> _U32) + (p01 & _M32) + (p10 & _M32)
        hi2 = a1 * b1 + (p01 >> _U32) + (p10 >> _U32) + (mid >> _U32)
        lo = lo + hi2
        if hi2 > lo:
            hi += _U1
    upper = hi >> _U63
    shift = upper + _U9
    mant = hi >> shift
    power2 = (((152170 + 65536) * q) >> 16) + 63 + int(upper) - lz + 1023
    if power2 <= 0:
        if -power2 + 1 >= 64:
            return 0.0
        mant >>= _u64(-power2 + 1)
        mant += mant & _U1
        mant >>= _U1
        # mant < 2^52: subnormal; mant == 2^52: rounded up to the smallest normal (same formula)
        return float(mant) * POW2[0]
    if lo <= _U1 and -4 <= q <= 23 and (mant & _U3) == _U1:
        if (mant << shift) == hi:
            mant &= ~_U1
    mant += mant & _U1
    mant >>= _U1
    if mant >= _TWO53:
        mant = _TWO52
        power2 += 1
    if power2 >= 2047:
        return math.inf
    return float(mant) * POW2[power2 - 1075 + 1074]


# -- reader -------------------------------------------------------------------------------------------------
# status codes of a field
_OK = 0
_FALLBACK = 1
_GARBAGE = 2


# the words a number field may spell, as byte arrays: a string literal would be a numba type of its own and compile
# _match_word once per word (only the kernels called from Python are cached; they hold their helpers)
_NAN = np.frombuffer(b"nan", np.uint8)
_INFINITY = np.frombuffer(b"infinity", np.uint8)
_INF = np.frombuffer(b"inf", np.uint8)


@njit(no_cpython_wrapper=True)  # only the blocks' kernels call it
def _lower(c: np.uint8) -> int:
    c = int(c)
    if 65 <= c <= 90:
        return c + 32
    return c


@njit(no_cpython_wrapper=True)  # only the blocks' kernels call it
def _match_word(buf: np.ndarray, p: int, end: int, word: np.ndarray) -> int:
    """Length of ``word`` (lower-case ASCII bytes) if buf[p:] starts with it (case-insensitive), else 0."""
    n = len(word)
    if p + n > end:
        return 0
    for k in range(n):
        if _lower(buf[p + k]) != word[k]:
            return 0
    return n


@njit(cache=True, nogil=True)
def parse_block(
    buf: np.ndarray,
    pos: int,
    end: int,
    ncol: int,
    sep: int,
    dec: int,
    out: np.ndarray,
    row: int,
    strict: bool,
    fb: np.ndarray,
    bad: np.ndarray,
    t_hi: np.ndarray,
    t_lo: np.ndarray,
) -> np.ndarray:
    """Parse whole lines of ``buf[pos:end]`` into ``out[row:]`` (float64, ncol columns).

    Returns int64 [pos, row, lines, nbad, nfb, stop] where ``lines`` counts the lines consumed (for line
    numbers), ``stop`` is 0 (done), 1 (out full), 2 (fallback list full) or 3 (bad row under ``strict``).
    ``fb`` rows get (row, col, start, stop) of tokens for Python's float(); ``bad`` rows get (line index,
    reason: 1 = field count, 2 = not a number, fields found) for the first rows skipped (all are counted).
    """
    nrow_cap = out.shape[0]
    nfb = 0
    nbad = 0
    lines = 0
    stop = 0
    fb_cap = fb.shape[0]
    bad_cap = bad.shape[0]
    ws2 = 9 if sep != 9 else 32  # a tab is blank space unless it is the separator
    while pos < end:
        p = pos
        while p < end and (buf[p] == 32 or buf[p] == ws2):
            p += 1
        if p >= end:
            pos = end
            break
        c0 = buf[p]
        if c0 == 10 or c0 == 35 or (c0 == 13 and p + 1 < end and buf[p + 1] == 10):
            while p < end and buf[p] != 10:
                p += 1
            pos = p + 1
            lines += 1
            continue
        if row >= nrow_cap:
            stop = 1
            break
        if nfb + ncol > fb_cap:
            stop = 2
            break
        col = 0
        status = _OK
        nfb0 = nfb
        while True:
            # -- one field: spaces, optional quote, number, optional quote, spaces --
            while p < end and (buf[p] == 32 or buf[p] == ws2):
                p += 1
            quoted = False
            if p < end and buf[p] == 34:
                quoted = True
                p += 1
            start = p
            neg = False
            if p < end and (buf[p] == 45 or buf[p] == 43):
                neg = buf[p] == 45
                p += 1
            # fast scan: every digit into w (exact while the token has at most 19 digits in all); four digits a
            # step where four follow (w·10⁴ + abcd is w's four single steps, modulo 2⁶⁴ alike, with a quarter
            # of the multiply-add chain that bounds this loop)
            w = _U0
            p0 = p
            while p < end:
                d = int(buf[p]) - 48
                if d < 0 or d > 9:
                    break
                w = w * _U10 + _u64(d)
                p += 1
            digits = p - p0
            q = 0
            if p < end and buf[p] == dec:
                p += 1
                p1 = p
                while p + 3 < end:
                    d0 = int(buf[p]) - 48
                    d1 = int(buf[p + 1]) - 48
                    d2 = int(buf[p + 2]) - 48
                    d3 = int(buf[p + 3]) - 48
                    if d0 < 0 or d0 > 9 or d1 < 0 or d1 > 9 or d2 < 0 or d2 > 9 or d3 < 0 or d3 > 9:
                        break
                    w = w * _E4 + _u64(d0 * 1000 + d1 * 100 + d2 * 10 + d3)
                    p += 4
                while p < end:
                    d = int(buf[p]) - 48
                    if d < 0 or d > 9:
                        break
                    w = w * _U10 + _u64(d)
                    p += 1
                q = p1 - p
                digits += p - p1
            many = False
            if digits > 19:
                # long token: keep the first 19 significant digits (leading zeros are not significant)
                p = p0
                w = _U0
                nd = 0
                q = 0
                seen_dec = False
                while p < end:
                    ch = int(buf[p])
                    if ch == dec and not seen_dec:
                        seen_dec = True
                        p += 1
                        continue
                    d = ch - 48
                    if d < 0 or d > 9:
                        break
                    if w != _U0 or d != 0:
                        if nd < 19:
                            w = w * _U10 + _u64(d)
                            nd += 1
                            if seen_dec:
                                q -= 1
                        else:
                            many = True
                            if not seen_dec:
                                q += 1
                    elif seen_dec:
                        q -= 1
                    p += 1
            fstat = _OK
            val = np.nan
            if digits > 0:
                if p < end and (buf[p] == 101 or buf[p] == 69):
                    p += 1
                    eneg = False
                    if p < end and (buf[p] == 45 or buf[p] == 43):
                        eneg = buf[p] == 45
                        p += 1
                    ev = 0
                    edig = 0
                    while p < end:
                        d = int(buf[p]) - 48
                        if d < 0 or d > 9:
                            break
                        if ev < 100000:
                            ev = ev * 10 + d
                        edig += 1
                        p += 1
                    if edig == 0:
                        fstat = _GARBAGE
                    elif ev >= 100000:
                        many = True
                    q += -ev if eneg else ev
                if fstat == _OK:
                    if many:
                        fstat = _FALLBACK
                    else:
                        val = decimal_to_double(w, q)
                        if neg:
                            val = -val
            elif p != p0:  # a decimal point and no digit (".", ".nan", "-.inf"): not a number float() reads
                fstat = _GARBAGE
            else:
                n = _match_word(buf, p, end, _NAN)
                if n:
                    p += n
                else:
                    n = _match_word(buf, p, end, _INFINITY)
                    if n == 0:
                        n = _match_word(buf, p, end, _INF)
                    if n:
                        p += n
                        val = -math.inf if neg else math.inf
                    elif p != start:  # a lone sign
                        fstat = _GARBAGE
            stop_tok = p
            if quoted and p < end and buf[p] == 34:
                p += 1
            while p < end and (buf[p] == 32 or buf[p] == ws2):
                p += 1
            if p < end and buf[p] != sep and buf[p] != 10 and buf[p] != 13:
                fstat = _GARBAGE
            if fstat == _GARBAGE:
                status = _GARBAGE
                break
            if col < ncol:
                out[row, col] = val
                if fstat == _FALLBACK:
                    fb[nfb, 0] = row
                    fb[nfb, 1] = col
                    fb[nfb, 2] = start
                    fb[nfb, 3] = stop_tok
                    nfb += 1
            col += 1
            if p < end and buf[p] == sep:
                p += 1
                continue
            break
        # rest of the line (a CR before LF, or garbage after a bad field)
        while p < end and buf[p] != 10:
            if buf[p] != 13:
                if status == _OK:
                    status = _GARBAGE
            p += 1
        pos = p + 1
        lines += 1
        if status == _OK and col != ncol:
            status = 3
        if status != _OK:
            nfb = nfb0
            if nbad < bad_cap:
                bad[nbad, 0] = lines - 1
                bad[nbad, 1] = 1 if status == 3 else 2
                bad[nbad, 2] = col
            nbad += 1
            if strict:
                stop = 3
                break
            continue
        row += 1
    if pos > end:
        pos = end
    res = np.empty(6, np.int64)
    res[0] = pos
    res[1] = row
    res[2] = lines
    res[3] = nbad
    res[4] = nfb
    res[5] = stop
    return res


# -- writer -------------------------------------------------------------------------------------------------
@njit(no_cpython_wrapper=True)  # only the blocks' kernels call it
def _round_shift(hi: np.uint64, lo: np.uint64, s: int) -> np.uint64:
    """round((hi·2^64 + lo) / 2^s) for 1 ≤ s ≤ 127 (result assumed < 2^64)."""
    s1 = s - 1
    if s1 >= 64:
        r = hi >> _u64(s1 - 64)
    elif s1 == 0:
        r = lo
    else:
        r = (hi << _u64(64 - s1)) | (lo >> _u64(s1))
    return (r + _U1) >> _U1


@njit(no_cpython_wrapper=True)  # only the blocks' kernels call it
def _digits17(m: np.uint64, e2: int, e10: int) -> np.uint64:
    """≈ round(m·2^e2 · 10^(16 - e10)) (within ±1) for an integer m < 2^53."""
    k = 16 - e10
    i = k - _W_MIN
    h1, l1 = _mul128(m, T_HI[i])
    h2, _l2 = _mul128(m, T_LO[i])
    lo = l1 + h2
    hi = h1
    if lo < h2:
        hi += _U1
    s = -(T_EXP[i] + e2 + k + 64)
    if s <= 0:
        return _MAXU
    if s > 127:
        return _U0
    return _round_shift(hi, lo, s)


@njit(no_cpython_wrapper=True)  # only the blocks' kernels call it
def shortest_digits(ax: float, b: np.uint64) -> tuple[np.uint64, int, int]:
    """(digits, n digits, decimal exponent E) with ax = d1.d2d3… × 10^E exactly on parsing; n = 0: failed.

    ``b`` is the bit pattern of ax (> 0, finite). Tries 15, then 16, then 17 significant digits.
    """
    ex = int((b >> _U52) & _M11)
    if ex == 0:  # subnormal: m·2^-1074 with m < 2^52
        m = b & _MANT
        e2 = -1074
        e10 = int(math.floor(math.log10(ax)))
    else:
        m = (b & _MANT) | _TWO52
        e2 = ex - 1075
        e10 = ((e2 + 52) * 1262611) >> 22  # ⌊(e2+52)·log10 2⌋
        if e10 + 1 <= 309 and ax >= P10F[e10 + 1 + 307]:
            e10 += 1
    d = _digits17(m, e2, e10)
    if d >= _E17:
        e10 += 1
        d = _digits17(m, e2, e10)
    elif d < _E16:
        e10 -= 1
        d = _digits17(m, e2, e10)
    if d >= _E17 or d < _E16:
        return _U0, 0, 0
    # A shorter candidate can only round-trip if it lies within half an ulp of x; in units of d the ulp of x is
    # d/m (1.1 … 22), so candidates farther away than that (+1 for d's own error) are not even tried.
    reach = 0.5 * float(d) / float(m) + 1.0
    # 15 digits
    r = int(d % _U100)
    if min(r, 100 - r) <= reach:
        c = (d + _U50) // _U100
        e = e10
        if c >= _E15:
            c = c // _U10
            e += 1
        if decimal_to_double(c, e - 14) == ax:
            return c, 15, e
    # 16 digits
    r = int(d % _U10)
    if min(r, 10 - r) <= reach:
        c = (d + _U5) // _U10
        e = e10
        if c >= _E16:
            c = c // _U10
            e += 1
        if decimal_to_double(c, e - 15) == ax:
            return c, 16, e
    # 17 digits: d, or its neighbour
    for delta in range(3):
        c = d if delta == 0 else (d - _U1 if delta == 1 else d + _U1)
        if decimal_to_double(c, e10 - 16) == ax:
            return c, 17, e10
    return _U0, 0, 0


MAX_FIELD_BYTES = 26  # sign, 17 digits, point, up to 4 leading zeros or 'e-308', separator


P10U = np.array([10**k for k in range(20)], np.uint64)
MAX_DECIMALS = 15


@njit(cache=True, nogil=True)
def format_block(
    data: np.ndarray,
    bits: np.ndarray,
    r0: int,
    r1: int,
    sep: int,
    out: np.ndarray,
    fails: np.ndarray,
    decimals: np.ndarray,
) -> tuple[int, int]:
    """Format rows data[r0:r1] (``bits`` = data.view(uint64)) as CSV lines into ``out`` (needs
    (r1-r0)·(ncol·MAX_FIELD_BYTES + 1) bytes). Layout as ``repr``: positional for 1e-4 ≤ |x| < 1e16, else
    ``d.ddde±XX``; integers without a trailing ``.0``; NaN = empty field; ±inf as ``inf``/``-inf``.

    ``decimals[j]`` ≥ 0 (≤ MAX_DECIMALS): column j is rounded to that many decimals instead (fixed point,
    trailing zeros dropped, ``-0`` written ``0``) — for estimator outputs whose resolution is stated in the
    file header; values too large for it (|x|·10^d ≥ 9e15) fall back to the exact form. −1: exact.

    Returns (bytes written, number of values that could not be formatted — never seen; their (row, col) go
    to ``fails`` and the caller re-formats those rows with Python's repr).
    """
    ncol = data.shape[1]
    tmp = np.empty(24, np.uint8)
    p = 0
    nf = 0
    for r in range(r0, r1):
        for j in range(ncol):
            if j:
                out[p] = sep
                p += 1
            x = data[r, j]
            if x != x:
                continue
            b = bits[r, j]
            if (b >> _U63) != _U0:
                out[p] = 45
                p += 1
                ax = -x
                b = b & _ABS
            else:
                ax = x
            if ax == 0.0:
                if decimals[j] >= 0 and (b != bits[r, j]):
                    p -= 1  # −0 in a fixed-decimals column: written 0, as a value that rounds to zero
                out[p] = 48
                p += 1
                continue
            if ax == math.inf:
                out[p] = 105
                out[p + 1] = 110
                out[p + 2] = 102
                p += 3
                continue
            dj = decimals[j]
            if dj >= 0:
                scaled = ax * P10F[dj + 307]
                if scaled < 9e15:
                    v = np.uint64(scaled + 0.5)
                    if v == _U0:
                        if x < 0:
                            p -= 1  # rounds to zero: no sign
                        out[p] = 48
                        p += 1
                        continue
                    # the decimals the outputs use divide by a constant (a multiply and a shift, where a division
                    # by a table's power of ten is a 64-bit divide, ~40 cycles); the fraction two digits a step
                    if dj == 6:
                        ip = v // _E6
                        fp = v - ip * _E6
                    elif dj == 9:
                        ip = v // _E9
                        fp = v - ip * _E9
                    else:
                        ip = v // P10U[dj]
                        fp = v - ip * P10U[dj]
                    k = 0
                    while True:  # integer part, reversed
                        tmp[k] = 48 + int(ip % _U10)
                        ip = ip // _U10
                        k += 1
                        if ip == _U0:
                            break
                    for i in range(k - 1, -1, -1):
                        out[p] = tmp[i]
                        p += 1
                    nd = dj
                    while nd > 1 and fp % _U100 == _U0:
                        fp = fp // _U100
                        nd -= 2
                    if nd > 0 and fp % _U10 == _U0:
                        fp = fp // _U10
                        nd -= 1
                    if nd > 0:
                        out[p] = 46
                        i = nd
                        while i > 1:
                            two = int(fp % _U100)
                            fp = fp // _U100
                            out[p + i] = DIGIT_PAIRS[2 * two + 1]
                            out[p + i - 1] = DIGIT_PAIRS[2 * two]
                            i -= 2
                        if i == 1:
                            out[p + 1] = 48 + int(fp)
                        p += nd + 1
                    continue
            c, nd, e = shortest_digits(ax, b)
            if nd == 0:
                if nf < fails.shape[0]:
                    fails[nf, 0] = r
                    fails[nf, 1] = j
                nf += 1
                continue
            while nd > 8 and c % _E8 == _U0:
                c = c // _E8
                nd -= 8
            while nd > 2 and c % _U100 == _U0:
                c = c // _U100
                nd -= 2
            while nd > 1 and c % _U10 == _U0:
                c = c // _U10
                nd -= 1
            k = nd - 1
            while k >= 1:  # two digits per division
                two = int(c % _U100)
                c = c // _U100
                tmp[k] = DIGIT_PAIRS[2 * two + 1]
                tmp[k - 1] = DIGIT_PAIRS[2 * two]
                k -= 2
            if k == 0:
                tmp[0] = 48 + int(c)
            if -4 <= e < 16:
                if e >= 0:
                    for k in range(nd):
                        if k == e + 1:
                            out[p] = 46
                            p += 1
                        out[p] = tmp[k]
                        p += 1
                    for _k in range(nd, e + 1):
                        out[p] = 48
                        p += 1
                else:
                    out[p] = 48
                    out[p + 1] = 46
                    p += 2
                    for _k in range(-e - 1):
                        out[p] = 48
                        p += 1
                    for k in range(nd):
                        out[p] = tmp[k]
                        p += 1
            else:
                out[p] = tmp[0]
                p += 1
                if nd > 1:
                    out[p] = 46
                    p += 1
                    for k in range(1, nd):
                        out[p] = tmp[k]
                        p += 1
                out[p] = 101
                p += 1
                if e < 0:
                    out[p] = 45
                    e = -e
                else:
                    out[p] = 43
                p += 1
                if e >= 100:
                    out[p] = 48 + e // 100
                    p += 1
                out[p] = 48 + (e // 10) % 10
                out[p + 1] = 48 + e % 10
                p += 2
        out[p] = 10
        p += 1
    return p, nf
