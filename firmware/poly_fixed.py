"""A polynomial in integer arithmetic (Horner with per-step scaling), for the control step.

`poly(x, k)` evaluates a polynomial exported by the host: Df_hat(D1) (um -> um), the force
model F0(d) (um -> mN) and its inverse d(F0) (mN -> um). The input is clamped to the declared
range and centred (u = x - XC) so that |u| is as small as the range allows. Each Horner
accumulator r_j = a_j + u * r_(j+1) is held as R_j = round(r_j * 2**E_j) with its own exponent
E_j, chosen by the host so that |R_j| <= 2**29 and |R_(j+1) * u| <= 2**29 over the whole input
range (host/fixed_export.py proves it from the coefficients and checks it by instrumentation).
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

try:
    import micropython  # @micropython.native is resolved by MicroPython's compiler, not at run time
except ImportError:  # CPython: the same decorator must still be valid, as an identity
    from firmware import portable as micropython


# native code: 2-3x faster under MicroPython and bit-identical (the same int objects and
# operators); only the literal @micropython.native selects the emitter (firmware.portable's
# `native` is an identity on MicroPython too, as the micropython module has no such attribute)
@micropython.native
def poly(x, k):
    """The exported polynomial `k` (layout above) at integer input `x`, as an integer."""
    if x < k[2]:
        x = k[2]
    elif x > k[3]:
        x = k[3]
    u = x - k[1]
    uh = u >> 8
    ul = u & 255
    r = k[5]
    i = 6
    end = 6 + (k[0] << 1)
    while i < end:
        sh = k[i]
        r = k[i + 1] + ((r * uh + ((r * ul + ((1 << sh) >> 1)) >> 8)) >> (sh - 8))
        i += 2
    e = k[4]
    return (r + ((1 << e) >> 1)) >> e
