"""The degree-3 rational Bernstein calibration (BCM-3) in integer arithmetic, for the control step.

`bcm3(code, k)` turns an ADC code into a position in integer micrometres. It is the rational de
Casteljau algorithm in affine form: every step blends two (weight, point) pairs with a convex
combination, so no value ever leaves the range spanned by the constants, and every intermediate
stays within +-2**30 (31-bit small ints on 32-bit boards). It allocates nothing and gives the same
bits under CPython and MicroPython (only +, -, *, <<, >>, & and //, whose rounding is floor on
both interpreters, also for negative numbers; every rounding is written as floor(v + 1/2)).

k layout (a flat int sequence, array('i') on the board; written by host/fixed_export.py):

    k[0]  S     input shift: the code is scaled to code << S (S = 20 - adc_bits)
    k[1]  LX    lowest pot output lx, in codes * 2**S (rounded), |LX| <= 2**20
    k[2]  RX    span rx = ux - lx, in codes * 2**S (rounded), 1 <= RX <= 2**20
    k[3]  H     handle shift: handles are stored in units of 2**-H um
    k[4:8]      weights w0..w3, integers, the largest 2**20, the smallest >= 1
    k[8:12]     handles p0..p3 in units of 2**-H um, max - min <= 2**20, |p| <= 2**29

Q formats: t in Q17, t = round((code * 2**S - LX) * 2**17 / RX) clamped to [0, 2**17]; the right
point's share l = t * w_b / w, also Q17 (clamped to 2**17, as rounding may push it a hair over);
weights plain integers up to 2**20. The prototype's Q15 t, Q14 share and 14-bit weights lost up
to 40 um at weight ratios of 60 (a weight of 273 rounds by 0.2 %), and a coarse t costs
(t step) x (local slope) wherever the curve is steep. Products of a Q17 number v (t or l, split
as v = vh * 2**8 + vl, vh <= 2**9) with a 20-bit weight or handle difference x are taken in
halves and recombined with nested floors, exactly floor((v * x + 2**16) / 2**17):

    (vh * x + ((vl * x + 2**16) >> 8)) >> 9       |vh * x| <= 2**29, |vl * x| < 2**28

and the divisions t * w_b / w and d * 2**17 / RX are long divisions in two digits, so no
intermediate exceeds 2**29 + 2**28. See docs/fixed-point.md for the bound analysis and the
measured figures.
"""

from firmware.portable import const

try:
    import micropython  # @micropython.native is resolved by MicroPython's compiler, not at run time
except ImportError:  # CPython: the same decorator must still be valid, as an identity
    from firmware import portable as micropython

_ONE = const(131072)  # 1.0 in Q17
_HALF = const(65536)

LENGTH = const(12)


# native code: 2-3x faster under MicroPython and bit-identical (the same int objects and
# operators); only the literal @micropython.native selects the emitter (firmware.portable's
# `native` is an identity on MicroPython too, as the micropython module has no such attribute)
@micropython.native
def bcm3(code, k):
    """Position in um of ADC `code` for the exported BCM-3 constants `k` (layout above)."""
    d = (code << k[0]) - k[1]
    rx = k[2]
    if d <= 0:
        t = 0
    elif d >= rx:
        t = _ONE
    else:
        q = d << 9
        t = q // rx
        t = (t << 8) + (((q - t * rx) << 8) + (rx >> 1)) // rx
    w0 = k[4]
    w1 = k[5]
    w2 = k[6]
    w3 = k[7]
    p0 = k[8]
    p1 = k[9]
    p2 = k[10]
    p3 = k[11]
    th = t >> 8
    tl = t & 255
    # Each blend of (wa, pa) and (wb, pb) at t, every product in halves (see the docstring):
    #   w = wa + round(t (wb - wa) / 2**17)
    #   l = min(round(t wb / w), 2**17)        the right point's share; w >= t wb / 2**17
    #   p = pa + round(l (pb - pa) / 2**17)
    # level 1: (0,1) -> a, (1,2) -> b, (2,3) -> c
    dw = w1 - w0
    wa = w0 + ((th * dw + ((tl * dw + _HALF) >> 8)) >> 9)
    q = th * w1
    l = q // wa
    l = (l << 8) + (((q - l * wa) << 8) + tl * w1 + (wa >> 1)) // wa
    if l > _ONE:
        l = _ONE
    dp = p1 - p0
    pa = p0 + (((l >> 8) * dp + (((l & 255) * dp + _HALF) >> 8)) >> 9)
    dw = w2 - w1
    wb = w1 + ((th * dw + ((tl * dw + _HALF) >> 8)) >> 9)
    q = th * w2
    l = q // wb
    l = (l << 8) + (((q - l * wb) << 8) + tl * w2 + (wb >> 1)) // wb
    if l > _ONE:
        l = _ONE
    dp = p2 - p1
    pb = p1 + (((l >> 8) * dp + (((l & 255) * dp + _HALF) >> 8)) >> 9)
    dw = w3 - w2
    wc = w2 + ((th * dw + ((tl * dw + _HALF) >> 8)) >> 9)
    q = th * w3
    l = q // wc
    l = (l << 8) + (((q - l * wc) << 8) + tl * w3 + (wc >> 1)) // wc
    if l > _ONE:
        l = _ONE
    dp = p3 - p2
    pc = p2 + (((l >> 8) * dp + (((l & 255) * dp + _HALF) >> 8)) >> 9)
    # level 2: (a,b) -> 0, (b,c) -> 1
    dw = wb - wa
    w0 = wa + ((th * dw + ((tl * dw + _HALF) >> 8)) >> 9)
    q = th * wb
    l = q // w0
    l = (l << 8) + (((q - l * w0) << 8) + tl * wb + (w0 >> 1)) // w0
    if l > _ONE:
        l = _ONE
    dp = pb - pa
    p0 = pa + (((l >> 8) * dp + (((l & 255) * dp + _HALF) >> 8)) >> 9)
    dw = wc - wb
    w1 = wb + ((th * dw + ((tl * dw + _HALF) >> 8)) >> 9)
    q = th * wc
    l = q // w1
    l = (l << 8) + (((q - l * w1) << 8) + tl * wc + (w1 >> 1)) // w1
    if l > _ONE:
        l = _ONE
    dp = pc - pb
    p1 = pb + (((l >> 8) * dp + (((l & 255) * dp + _HALF) >> 8)) >> 9)
    # level 3: (0,1) -> the point on the curve
    dw = w1 - w0
    w2 = w0 + ((th * dw + ((tl * dw + _HALF) >> 8)) >> 9)
    q = th * w1
    l = q // w2
    l = (l << 8) + (((q - l * w2) << 8) + tl * w1 + (w2 >> 1)) // w2
    if l > _ONE:
        l = _ONE
    dp = p1 - p0
    pa = p0 + (((l >> 8) * dp + (((l & 255) * dp + _HALF) >> 8)) >> 9)
    h = k[3]
    if h:
        return (pa + (1 << (h - 1))) >> h
    return pa
