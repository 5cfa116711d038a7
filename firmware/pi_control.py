"""Fixed-point PI controller with anti-windup, output limit and slew limit (allocation-free).

Units: the error is an integer (um of position or of spring deformation), the output a signed
duty in [-DUTY_MAX, DUTY_MAX]. Gains are Q8 integers:
    P term  = kp * e / 256                      (kp = 256 means 1 duty count per um)
    I state = sum(ki * e / 256), kept in Q8 duty (1/256 duty count), clamped to +-int_limit duty
Bounds that keep every intermediate within +-2**30 on 32-bit boards: |e| is clamped to
E_MAX = 32767 and the gains to 0..32767, so |kp * e| <= 32767**2 < 2**30; the P term is then
<= 2**22, the I state <= 10000 * 256 < 2**22, and their sum stays far below 2**30.
"""

from firmware.portable import const

DUTY_MAX = const(10000)  # signed duty range of the whole firmware: 10000 = 100.00 %
E_MAX = const(32767)
GAIN_MAX = const(32767)
Q = const(8)


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
    """One PI loop. `integ` is the integral state in Q8 duty; reset() clears it."""

    def __init__(self):
        self.integ = 0
        self.out = 0
        self.saturated = 0  # +1 / -1 when the last output hit the limit, else 0

    def reset(self):
        self.integ = 0
        self.out = 0
        self.saturated = 0

    def update(self, e, kp, ki, out_limit, int_limit):
        if e > E_MAX:
            e = E_MAX
        elif e < -E_MAX:
            e = -E_MAX
        p = (kp * e) >> Q
        # Anti-windup (conditional integration): do not integrate an error that pushes further
        # into a limit the output is already at, whether this step's output limit or (flag from
        # applied()) the stroke and slew limits downstream.
        u = p + (self.integ >> Q)
        push = 1 if (u >= out_limit or self.saturated > 0) else (-1 if (u <= -out_limit or self.saturated < 0) else 0)
        if not ((push > 0 and e > 0) or (push < 0 and e < 0)):
            lim = int_limit << Q
            self.integ = clamp(self.integ + ((ki * e) >> Q), -lim, lim)
            u = p + (self.integ >> Q)
        if u >= out_limit:
            u = out_limit
            self.saturated = 1
        elif u <= -out_limit:
            u = -out_limit
            self.saturated = -1
        else:
            self.saturated = 0
        self.out = u
        return u

    def applied(self, duty):
        """Tell the loop what actually reached the motor after stroke and slew limits: when
        less than asked in the output's direction, treat it as saturated (no wind-up)."""
        u = self.out
        if u > 0 and duty < u:
            self.saturated = 1
        elif u < 0 and duty > u:
            self.saturated = -1
