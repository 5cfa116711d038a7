"""The degree-3 rational Bernstein calibration (BCM-3) in integer arithmetic, for the control step.

`bcm3(code, k)` turns an ADC code into a position in integer micrometres. It allocates nothing,
keeps every intermediate within +-2**30 (31-bit small ints on 32-bit boards) and gives the same
bits under CPython and MicroPython (only +, -, *, <<, >>, & and //, whose rounding is floor on
both interpreters, also for negative numbers; every rounding is written as floor(v + 1/2)).

Why not de Casteljau on a fixed-point t: a curve whose weight ratios reach the fitter's box
(w_i / w_0 in [1/60, 60], so up to 3600 between two weights) can rise by tens of millimetres
within one ADC code near an end of its range. Half an LSB there needs t to ~2**-28 and the small
weights to ~2**-16 of themselves, which fixed-point blends of 31-bit ints cannot carry. But the
steep places are always near an end (a crossover of two Bernstein terms at t has a slope of at
most 3 / (4 t (1 - t)) per unit of t), so what is needed is *relative* precision there, which a
mantissa and an exponent give. With a = t and b = 1 - t scaled to the input (a + b = RX):

    f = sum_i c_i u^i p_i / sum_i c_i u^i,   u = a / b <= 1,  c_i = C(3, i) w_i / w_0

evaluated from the nearer end (a > b: u = b / a, c'_i = C(3, i) w_(3-i) / w_3, handles reversed).
Each term c_i u^i is a 19-bit mantissa m in [2**18, 2**19] with an exponent e (value m / 2**e),
correct to about 2**-15 of itself; a relative error r in every term moves f by at most
r * max|p_i - f|, so the position error stays below ~2**-14 of the handle spread however steep
the curve. The terms are then aligned to the largest and blended one by one into a running
weighted mean with Q16 shares, so the point never leaves the range of the handles.

k layout (a flat int sequence, array('i') on the board; written by host/calibration/fixed_export.py):

    k[0]      S     input shift: codes are scaled by 2**S, S = 29 - adc_bits
    k[1]      LX    lowest pot output lx in codes * 2**S (rounded), 0 <= LX
    k[2]      RX    span rx in codes * 2**S (rounded), 2**19 <= RX, LX + RX <= 2**29
    k[3]      KB    shift taking RX to 20 bits: 2**19 <= RX >> KB < 2**20
    k[4]      H     handle shift: handles are stored in units of 2**-H um
    k[5:9]          handles p0..p3, max - min <= 2**21, -2**29 <= p < 2**29
    k[9:15]         c_1, c_2, c_3 from the low end as (mantissa, exponent) pairs, c = m / 2**e
    k[15:21]        c'_1, c'_2, c'_3 from the high end, likewise; mantissas in [2**18, 2**19]

A product of two mantissas x, y in [2**18, 2**20] is taken in halves (x = xh * 2**10 + xl) and
recombined with nested floors, exactly floor((x * y + 2**17) / 2**18):

    ((x >> 10) * y + (((x & 1023) * y + 2**17) >> 10)) >> 8     |(x >> 10) * y| <= 2**29

See docs/fixed-point.md for the bound of every intermediate and the measured figures.
"""

from firmware.portable import const, ptr32

try:
    import micropython  # @micropython.viper is resolved by MicroPython's compiler, not at run time
except ImportError:  # CPython: the same decorator must still be valid, as an identity
    from firmware import portable as micropython

LENGTH = const(21)
_M19 = const(524288)  # 2**19: a mantissa at or above it is halved
_M18 = const(262144)  # 2**18: 1.0 as a mantissa with exponent 18
_R17 = const(131072)  # 2**17: rounding offset of a mantissa product
_B29 = const(536870912)  # [sign-fix] 2**29 and 2**30 - 1 (docs/firmware.md, Viper idioms)
_M30 = const(1073741823)


# [viper-bits] and [sign-fix] (docs/firmware.md, Viper idioms): handles and exponents may be negative.
@micropython.viper
def bcm3(code: int, kk) -> int:
    """Position in um of ADC `code` for the exported BCM-3 constants `kk` (layout above)."""
    k = ptr32(kk)
    s = k[0]
    h = k[4]
    if code < 0:
        code = 0
    elif code >> (29 - s):  # beyond the ADC's range: the curve's high end (and no overflow)
        code = 1 << (29 - s)
    a = (code << s) - k[1]  # distance from the low end
    rx = k[2]
    b = rx - a  # distance from the high end
    if a <= 0:
        return ((((k[5] + _B29) & _M30) - _B29) + ((1 << h) >> 1)) >> h
    if b <= 0:
        return ((((k[8] + _B29) & _M30) - _B29) + ((1 << h) >> 1)) >> h
    if a <= b:  # u = a / b from the low end: handles p0, p1, p2, p3, ratios at k[9]
        j = 5
        step = 1
        c = 9
    else:  # u = b / a from the high end: handles p3, p2, p1, p0, ratios at k[15]
        j = 8
        step = -1
        c = 15
        a = b
        b = rx - a
    # u = a / b: b is within a factor 2 of RX (a + b = RX, a <= b), so one fixed shift takes it
    # to 19-20 bits; a can be anything from 1 to RX / 2 and is normalised to [2**19, 2**20]
    kb = k[3]
    b = (b + ((1 << kb) >> 1)) >> kb
    e = 18 + kb  # u = mu / 2**e once mu is known
    if a < _M19:
        if a < 16:
            a <<= 16
            e += 16
        if a < 4096:
            a <<= 8
            e += 8
        if a < 65536:
            a <<= 4
            e += 4
        if a < _M18:
            a <<= 2
            e += 2
        if a < _M19:
            a <<= 1
            e += 1
    elif a >= 1048576:
        n = 1
        v = a >> 20
        if v >= 256:
            v >>= 8
            n += 8
        if v >= 16:
            v >>= 4
            n += 4
        if v >= 4:
            v >>= 2
            n += 2
        if v >= 2:
            n += 1
        a = (a + (1 << (n - 1))) >> n
        e -= n
    # mu = round(a * 2**18 / b) by long division in two 9-bit digits (a << 9 <= 2**29)
    q = (a << 9) // b
    mu = (q << 9) + ((((a << 9) - q * b) << 9) + (b >> 1)) // b
    if mu >= _M19:
        mu = (mu + 1) >> 1
        e -= 1
    elif mu < _M18:
        mu <<= 1
        e += 1
    # u^2 and u^3 (mantissa, exponent), each renormalised to [2**18, 2**19]
    m2 = ((mu >> 10) * mu + (((mu & 1023) * mu + _R17) >> 10)) >> 8
    e2 = e + e - 18
    if m2 >= _M19:
        m2 = (m2 + 1) >> 1
        e2 -= 1
    m3 = ((m2 >> 10) * mu + (((m2 & 1023) * mu + _R17) >> 10)) >> 8
    e3 = e2 + e - 18
    if m3 >= _M19:
        m3 = (m3 + 1) >> 1
        e3 -= 1
    # the terms c_i u^i (term 0 is 1: mantissa 2**18, exponent 18)
    x = k[c]
    t1 = ((x >> 10) * mu + (((x & 1023) * mu + _R17) >> 10)) >> 8
    e1 = (((k[c + 1] + _B29) & _M30) - _B29) + e - 18
    x = k[c + 2]
    t2 = ((x >> 10) * m2 + (((x & 1023) * m2 + _R17) >> 10)) >> 8
    e2 = (((k[c + 3] + _B29) & _M30) - _B29) + e2 - 18
    x = k[c + 4]
    t3 = ((x >> 10) * m3 + (((x & 1023) * m3 + _R17) >> 10)) >> 8
    e3 = (((k[c + 5] + _B29) & _M30) - _B29) + e3 - 18
    # align every term to the largest exponent class, one bit lower so four of them sum to
    # at most 2**21; a term 2**-21 below the largest is dropped (its share is under 2**-20)
    top = 18
    if e1 < top:
        top = e1
    if e2 < top:
        top = e2
    if e3 < top:
        top = e3
    n = 19 - top
    t0 = (_M18 + ((1 << n) >> 1)) >> n if n < 22 else 0
    n = e1 - top + 1
    t1 = (t1 + ((1 << n) >> 1)) >> n if n < 22 else 0
    n = e2 - top + 1
    t2 = (t2 + ((1 << n) >> 1)) >> n if n < 22 else 0
    n = e3 - top + 1
    t3 = (t3 + ((1 << n) >> 1)) >> n if n < 22 else 0
    # running weighted mean of the handles: p += l (p_i - p), l = t_i / (sum so far) in Q16
    p = ((k[j] + _B29) & _M30) - _B29
    w = t0
    if t1:
        w += t1
        q = (t1 << 8) // w
        x = (q << 8) + (((((t1 << 8) - q * w) << 8) + (w >> 1)) // w)
        d = (((k[j + step] + _B29) & _M30) - _B29) - p
        p += ((x >> 8) * d + (((x & 255) * d + 32768) >> 8)) >> 8
    if t2:
        w += t2
        q = (t2 << 8) // w
        x = (q << 8) + (((((t2 << 8) - q * w) << 8) + (w >> 1)) // w)
        d = (((k[j + step + step] + _B29) & _M30) - _B29) - p
        p += ((x >> 8) * d + (((x & 255) * d + 32768) >> 8)) >> 8
    if t3:
        w += t3
        q = (t3 << 8) // w
        x = (q << 8) + (((((t3 << 8) - q * w) << 8) + (w >> 1)) // w)
        d = (((k[j + 3 * step] + _B29) & _M30) - _B29) - p
        p += ((x >> 8) * d + (((x & 255) * d + 32768) >> 8)) >> 8
    return (p + ((1 << h) >> 1)) >> h


def invalid(k):
    """Why `k` cannot be a bcm3 constant set (a string), or None: the layout limits above, which
    keep every intermediate within 2**30 and every shift small. The calibration loader uses it."""
    if len(k) != LENGTH:
        return "bcm3 needs %d values" % LENGTH
    s, lx, rx, kb, h = k[0], k[1], k[2], k[3], k[4]
    if not (0 <= s <= 28 and lx >= 0 and rx >= _M19 and lx + rx <= 1 << 29):
        return "bad input scaling"
    if not (0 <= kb <= 10 and _M19 <= rx >> kb < 1 << 20):
        return "bad span shift"
    if not 0 <= h <= 8:
        return "bad handle shift"
    p = k[5:9]
    if max(p) - min(p) > 1 << 21 or not -_B29 <= min(p) <= max(p) < _B29:
        return "handles out of range"
    for i in range(9, 21, 2):  # exponents within [-64, 64]: well inside the sign fix's range
        if not (_M18 <= k[i] <= _M19 and -64 <= k[i + 1] <= 64):
            return "bad weight ratio"
    return None
