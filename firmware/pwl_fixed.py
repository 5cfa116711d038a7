"""A piecewise-linear calibration table in integer arithmetic, for the control step.

`pwl(code, k)` turns an ADC code into a position in integer micrometres by binary search over
the knot codes and integer interpolation between the two neighbouring knots, clamped to the end
values outside the table. It serves the host's `lut` and `pwl` models and any curve tabulated
densely (e.g. a BCM of degree > 3, whose integer form would not stay within 31 bits).

k layout (a flat int sequence, array('i') on the board; written by host/calibration/fixed_export.py):

    k[0]            N   number of knots (>= 2)
    k[1]            S   input shift: the code is scaled to code << S (S = 16 - adc_bits)
    k[2 : 2+N]          knot codes * 2**S (rounded), strictly increasing, within [0, 2**16]
    k[2+N : 2+2N]       knot values in um

Every segment satisfies (x[i+1] - x[i]) * |y[i+1] - y[i]| <= 2**30 - 2**15 (the exporter splits
longer segments), so the interpolation product and its rounding offset stay within +-2**30.
Rounding is floor(v + 1/2) via // (floor on both interpreters, also for negative v). The value
at a knot is exactly the stored knot value, so a monotone table stays monotone.
"""

from firmware.portable import const, ptr32

try:
    import micropython  # @micropython.viper is resolved by MicroPython's compiler, not at run time
except ImportError:  # CPython: the same decorator must still be valid, as an identity
    from firmware import portable as micropython

# A force table (F0(d) or d(F0)) takes a signed input (d in um, F0 in mN) plus this, so that its
# knot "codes" lie in 0..2**16 like an ADC table's, with input shift 0.
FORCE_PWL_OFFSET = 32768
# A Df table takes D1 in units of 2 um plus this (df_table_input): pot 1's mounting error can put
# D1 anywhere from about -5 to 65 mm, more than 2**16 um, and a 2 um step of D1 moves Df by far
# less than 1 um.
DF_PWL_OFFSET = 32768


def df_table_input(d1_um):
    """The input of a Df table for D1 in um (the step inlines the same expression)."""
    return (d1_um >> 1) + DF_PWL_OFFSET

_B29 = const(536870912)  # [sign-fix] of a knot value (docs/firmware.md, Viper idioms)
_M30 = const(1073741823)


# viper: machine-word integers (bcm_fixed.py says why this is bit-identical on every port).
# Knot codes are never negative; knot values may be, and go through the sign fix.
@micropython.viper
def pwl(code: int, kk) -> int:
    """Position in um of ADC `code` for the exported table `kk` (layout above)."""
    k = ptr32(kk)
    n = k[0]
    x = code << k[1]
    last = n + 1  # index of the last knot code
    if x <= k[2]:
        return ((k[2 + n] + _B29) & _M30) - _B29
    if x >= k[last]:
        return ((k[last + n] + _B29) & _M30) - _B29
    lo = 2
    hi = last
    # invariant: k[lo] <= x < k[hi]
    while hi - lo > 1:
        mid = (lo + hi) >> 1
        if k[mid] <= x:
            lo = mid
        else:
            hi = mid
    x0 = k[lo]
    dx = k[hi] - x0
    y0 = ((k[lo + n] + _B29) & _M30) - _B29
    return y0 + ((x - x0) * ((((k[hi + n] + _B29) & _M30) - _B29) - y0) + (dx >> 1)) // dx
