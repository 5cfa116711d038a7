"""Fixed-point PI controller with anti-windup, output limit and slew limit (allocation-free).

Units: the error is an integer (um of position or of spring deformation), the output a signed
duty in [-DUTY_MAX, DUTY_MAX]. Gains are Q8 integers:
    P term  = kp * e / 256                      (kp = 256 means 1 duty count per um)
    I state = sum(ki * e / 256), kept in Q8 duty (1/256 duty count), clamped to +-int_limit duty
Bounds that keep every intermediate within +-2**30 on 32-bit boards: |e| is clamped to
E_MAX = 32767 and the gains to 0..32767, so |kp * e| <= 32767**2 < 2**30; the P term is then
<= 2**22, the I state <= 10000 * 256 < 2**22, and their sum stays far below 2**30.
The loop's state is one int32 block, `PI.st`; `integ`, `out` and `saturated` are properties.
"""

from firmware.portable import const, ptr32, word_property, zeros

try:
    import micropython  # @micropython.viper is resolved by MicroPython's compiler
except ImportError:  # CPython
    from firmware import portable as micropython

DUTY_MAX = const(10000)  # signed duty range of the whole firmware: 10000 = 100.00 %
E_MAX = const(32767)
GAIN_MAX = const(32767)
Q = const(8)

# [sign-fix] (docs/firmware.md, Viper idioms): a word that may be negative is read as ((v + _B29) & _M30) - _B29
_B29 = const(536870912)
_M30 = const(1073741823)

# PI.st
INTEG = const(0)  # integral, Q8 duty
OUT = const(1)  # the last output
SAT = const(2)  # +1 / -1 when the last output hit a limit (its own or downstream), else 0


def clamp(x, lo, hi):
    if x < lo:
        return lo
    if x > hi:
        return hi
    return x


def slew(prev, cmd, step):
    """Move from prev toward cmd by at most `step` (step <= 0 means no limit)."""
    if step <= 0:
        return cmd
    if cmd > prev + step:
        return prev + step
    if cmd < prev - step:
        return prev - step
    return cmd


class PI:
    """One PI loop; reset() clears it."""

    def __init__(self):
        self.st = zeros(3)

    integ = word_property(INTEG)
    out = word_property(OUT)
    saturated = word_property(SAT)

    def reset(self):
        st = self.st
        st[INTEG] = 0
        st[OUT] = 0
        st[SAT] = 0

    @micropython.viper
    def update(self, e: int, kp: int, ki: int, out_limit: int, int_limit: int) -> int:
        s = ptr32(self.st)
        if e > E_MAX:
            e = E_MAX
        elif e < -E_MAX:
            e = -E_MAX
        p = (kp * e) >> Q
        # Anti-windup (conditional integration): do not integrate an error that pushes further
        # into a limit the output is already at, whether this step's output limit or (flag from
        # applied()) the stroke and slew limits downstream.
        integ = ((s[INTEG] + _B29) & _M30) - _B29
        sat = ((s[SAT] + _B29) & _M30) - _B29
        u = p + (integ >> Q)
        push = 0
        if u >= out_limit or sat > 0:
            push = 1
        elif u <= -out_limit or sat < 0:
            push = -1
        if not ((push > 0 and e > 0) or (push < 0 and e < 0)):
            lim = int_limit << Q
            integ += (ki * e) >> Q
            if integ > lim:
                integ = lim
            elif integ < -lim:
                integ = -lim
            s[INTEG] = integ
            u = p + (integ >> Q)
        if u >= out_limit:
            u = out_limit
            s[SAT] = 1
        elif u <= -out_limit:
            u = -out_limit
            s[SAT] = -1
        else:
            s[SAT] = 0
        s[OUT] = u
        return u

    @micropython.viper
    def applied(self, duty: int):
        """Tell the loop what actually reached the motor after stroke and slew limits: when
        less than asked in the output's direction, treat it as saturated (no wind-up)."""
        s = ptr32(self.st)
        u = ((s[OUT] + _B29) & _M30) - _B29
        if u > 0 and duty < u:
            s[SAT] = 1
        elif u < 0 and duty > u:
            s[SAT] = -1
