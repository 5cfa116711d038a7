"""H-bridge output: a signed duty in [-DUTY_MAX, DUTY_MAX] to the board's bridge wiring.

Two wirings, chosen by the board file's "driver":
- "two_pwm" (DRV8833-style IN1/IN2): forward = PWM on IN1, IN2 low; reverse the other way.
  Both low is coast, so off() leaves the motor unpowered.
- "pwm_dir" (TB6612-style PWM + DIR): PWM on the enable, DIR selects the direction; an optional
  "dir_n" pin is driven as DIR's complement (the TB6612 wants AIN1/AIN2 opposite to drive).
Positive duty drives the nut toward larger D1 (set "motor_invert": true in the board file if the
motor is wired the other way).
"""

from firmware import hal
from firmware.portable import const

try:
    import micropython  # @micropython.viper is resolved by MicroPython's compiler
except ImportError:  # CPython
    from firmware import portable as micropython

TWO_PWM = const(0)
PWM_DIR = const(1)
_DUTY_MAX = const(10000)  # pi_control.DUTY_MAX as a compile-time constant for viper (tested equal)


class Motor:
    def __init__(self, machine, board):
        pins = board["motor_pins"]
        freq = board.get("pwm_freq", 20000)
        timers = board.get("pwm_timers", {})
        self.sign = -1 if board.get("motor_invert") else 1
        self.duty = 0
        self.pwm_b = None
        self.dir = None
        self.dir_n = None
        self._fwd = -1  # direction last driven (1 forward, 0 reverse); -1 = not yet / after off()
        self._u16 = -1  # duty_u16 last written to the driven channel; -1 = not yet / after off()
        if board["driver"] == "two_pwm":
            self.kind = TWO_PWM
            self.pwm_a = hal.pwm(machine, pins["in1"], freq, timers.get("in1"))
            self.pwm_b = hal.pwm(machine, pins["in2"], freq, timers.get("in2"))
        elif board["driver"] == "pwm_dir":
            self.kind = PWM_DIR
            self.pwm_a = hal.pwm(machine, pins["pwm"], freq, timers.get("pwm"))
            self.dir = hal.out_pin(machine, pins["dir"])
            if "dir_n" in pins:
                self.dir_n = hal.out_pin(machine, pins["dir_n"])
        else:
            raise ValueError("unknown driver %r (two_pwm or pwm_dir)" % board["driver"])
        self.off()

    @micropython.viper
    def set(self, duty: int):
        """Drive with a signed duty; values beyond +-DUTY_MAX are clamped. Allocation-free.
        Writes only what changes: the idle channel is zeroed when the direction changes (and by
        off()), and an unchanged duty is not written again (one C call per step, or none)."""
        if duty > _DUTY_MAX:
            duty = _DUTY_MAX
        elif duty < -_DUTY_MAX:
            duty = -_DUTY_MAX
        self.duty = duty
        d = duty * int(self.sign)
        fwd = 1
        if d < 0:
            fwd = 0
            d = -d
        u16 = (d * 65535) // _DUTY_MAX  # <= 655 350 000 < 2**30
        a = self.pwm_a
        if int(self.kind) == TWO_PWM:
            if int(self._fwd) != fwd:
                # the channel that drove the old direction goes to 0 first
                if fwd:
                    self.pwm_b.duty_u16(0)
                else:
                    a.duty_u16(0)
                self._fwd = fwd
                self._u16 = -1
            if int(self._u16) != u16:
                if fwd:
                    a.duty_u16(u16)
                else:
                    self.pwm_b.duty_u16(u16)
                self._u16 = u16
        else:
            # Duty to 0 before flipping the direction, so the bridge never drives the old
            # duty the wrong way for a moment.
            if int(self._fwd) != fwd:
                a.duty_u16(0)
                self.dir.value(fwd)
                dn = self.dir_n
                if dn:
                    dn.value(1 - fwd)
                self._fwd = fwd
                self._u16 = -1
            if int(self._u16) != u16:
                a.duty_u16(u16)
                self._u16 = u16

    def off(self):
        """Motor unpowered. Must not fail: called on every exit and fault path."""
        self.duty = 0
        self._u16 = -1  # the next set() writes its duty whatever it is
        self._fwd = -1
        self.pwm_a.duty_u16(0)
        if self.pwm_b is not None:
            self.pwm_b.duty_u16(0)

    def deinit(self):
        self.off()
        for p in (self.pwm_a, self.pwm_b):
            if p is not None and hasattr(p, "deinit"):
                p.deinit()
