"""A polynomial in integer arithmetic (Horner with per-step scaling), for the control step.

`poly(x, k)` evaluates a polynomial exported by the host: Df_hat(D1) (um -> um), the force
model F0(d) (um -> mN) and its inverse d(F0) (mN -> um). The input is clamped to the declared
range and centred (u = x - XC) so that |u| is as small as the range allows. Each Horner
accumulator r_j = a_j + u * r_(j+1) is held as R_j = round(r_j * 2**E_j) with its own exponent
E_j, chosen by the host so that |R_(j+1)| * max(256, |uh|) <= 2**29 over the whole input range;
every A_j, XC, XLO and XHI is within [-2**29, 2**29). `invalid(k)` proves those bounds from the
words alone (interval arithmetic, below), so the board refuses any polynomial that could leave
31 bits for some input, whoever wrote it; the host exports only polynomials it accepts.
The product R_(j+1) * u is taken in halves, u = uh * 2**8 + ul with 0 <= ul < 256, and
recombined with nested floors, exactly floor((R u + 2**(SH-1)) / 2**SH) for SH >= 8, so R only
has to satisfy |R| * max(256, |uh|) <= 2**29: about 21 bits for a 60 mm range in um, where a
whole product would leave R about 14.

k layout (a flat int sequence, array('i') on the board):

    k[0]  N     degree
    k[1]  XC    centre of the input range (input units)
    k[2]  XLO   lowest input, k[3] XHI highest input (the input is clamped to these)
    k[4]  E0    exponent of the last accumulator: the result is round(R_0 / 2**E0)
    k[5]        A_N = round(a_N * 2**E_N)
    then for j = N-1 down to 0, two words: SH_j = E_(j+1) - E_j (8..30) and A_j

    R_j = A_j + round(R_(j+1) * u / 2**SH_j)

Rounding is floor(v + 1/2) via >> (floor on both interpreters, also for negative v).
"""

from firmware.portable import const, ptr32

try:
    import micropython  # @micropython.viper is resolved by MicroPython's compiler, not at run time
except ImportError:  # CPython: the same decorator must still be valid, as an identity
    from firmware import portable as micropython

_B29 = const(536870912)  # [sign-fix] (docs/firmware.md, Viper idioms)
_M30 = const(1073741823)


# viper: machine-word integers (bcm_fixed.py says why this is bit-identical on every port).
# XC, XLO, XHI and every A_j may be negative and go through the sign fix (all < 2**29 in size).
@micropython.viper
def poly(x: int, kk) -> int:
    """The exported polynomial `kk` (layout above) at integer input `x`, as an integer."""
    k = ptr32(kk)
    lo = ((k[2] + _B29) & _M30) - _B29
    hi = ((k[3] + _B29) & _M30) - _B29
    if x < lo:
        x = lo
    elif x > hi:
        x = hi
    u = x - (((k[1] + _B29) & _M30) - _B29)
    uh = u >> 8
    ul = u & 255
    r = ((k[5] + _B29) & _M30) - _B29
    i = 6
    end = 6 + (k[0] << 1)
    while i < end:
        sh = k[i]
        a = ((k[i + 1] + _B29) & _M30) - _B29
        r = a + ((r * uh + ((r * ul + ((1 << sh) >> 1)) >> 8)) >> (sh - 8))
        i += 2
    e = k[4]
    return (r + ((1 << e) >> 1)) >> e


_PIECES = const(32)  # input pieces of the proof: more are tighter and slower (it runs once, at boot)


def _horner_step(r, u, sh, a):
    """One step of `poly` in plain integers, the same expression: a + floor((r u + 2**(sh-1)) / 2**sh)."""
    return a + ((r * (u >> 8) + ((r * (u & 255) + ((1 << sh) >> 1)) >> 8)) >> (sh - 8))


def overflow(k):
    """Why `poly(x, k)` could leave 31 bits for some input x (a string), or None when it cannot.

    The proof: split the inputs the evaluator can see (it clamps x to [XLO, XHI]) into pieces
    [ua, ub] of u = x - XC, and carry an interval [lo, hi] holding every accumulator R_j of the
    piece. A step maps R to A + floor((R u + 2**(SH-1)) / 2**SH), which grows with the product R u,
    and a product over a box takes its extremes at the corners, so the step's four corner values
    bound the next R; before each step |R| * max(256, |uh|) <= 2**29 is required, which keeps every
    intermediate of the step (r * uh, r * ul + 2**(SH-1), their sums) within 2**30, and the
    final rounding must stay below 2**30. Every value here is within 2**30 too, so the proof
    itself runs in small ints. The layout must already have passed the range checks of `invalid`.
    """
    n = k[0]
    ulo = k[2] - k[1]
    span = k[3] - k[2]
    pieces = min(_PIECES, span) or 1
    step = span // pieces
    for p in range(pieces):
        ua = ulo + step * p
        ub = ulo + span if p == pieces - 1 else ua + step
        mult = max(256, abs(ua >> 8), abs(ub >> 8))
        lo = hi = k[5]
        for j in range(n):
            if max(-lo, hi) > _B29 // mult:
                return "Horner step %d can exceed 31 bits for inputs %d..%d" % (n - j, ua + k[1], ub + k[1])
            sh = k[6 + 2 * j]
            a = k[7 + 2 * j]
            c1 = _horner_step(lo, ua, sh, a)
            c2 = _horner_step(lo, ub, sh, a)
            c3 = _horner_step(hi, ua, sh, a)
            c4 = _horner_step(hi, ub, sh, a)
            lo = min(c1, c2, c3, c4)
            hi = max(c1, c2, c3, c4)
        if max(-lo, hi) >= 2 * _B29 - ((1 << k[4]) >> 1):
            return "polynomial output can exceed 31 bits for inputs %d..%d" % (ua + k[1], ub + k[1])
    return None


def invalid(k):
    """Why `k` cannot be a poly constant set (a string), or None: the layout's limits, among them
    every word the evaluator sign-fixes within [-2**29, 2**29). The calibration loader uses it."""
    n = k[0]
    if not (0 <= n <= 30 and len(k) == 6 + 2 * n):
        return "polynomial length does not match its degree"
    if not (k[2] <= k[3] and 0 <= k[4] <= 30):
        return "bad input range or output shift"
    i = 6
    while i < len(k):
        if not 8 <= k[i] <= 30:
            return "bad Horner shift"
        i += 2
    for i in [1, 2, 3, 5] + list(range(7, len(k), 2)):
        if not -_B29 <= k[i] < _B29:
            return "coefficient or range beyond 2**29"
    return overflow(k)
