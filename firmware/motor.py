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
from firmware.pi_control import DUTY_MAX
from firmware.portable import const

TWO_PWM = const(0)
PWM_DIR = const(1)


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
        self._fwd = -1  # direction last written to DIR; -1 = not yet
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

    def set(self, duty):
        """Drive with a signed duty; values beyond +-DUTY_MAX are clamped. Allocation-free."""
        if duty > DUTY_MAX:
            duty = DUTY_MAX
        elif duty < -DUTY_MAX:
            duty = -DUTY_MAX
        self.duty = duty
        d = duty * self.sign
        mag = d if d >= 0 else -d
        u16 = (mag * 65535) // DUTY_MAX  # <= 655 350 000 < 2**30
        if self.kind == TWO_PWM:
            if d >= 0:
                self.pwm_b.duty_u16(0)
                self.pwm_a.duty_u16(u16)
            else:
                self.pwm_a.duty_u16(0)
                self.pwm_b.duty_u16(u16)
        else:
            # Duty to 0 before flipping the direction, so the bridge never drives the old
            # duty the wrong way for a moment.
            fwd = 1 if d >= 0 else 0
            if self._fwd != fwd:
                self.pwm_a.duty_u16(0)
                self.dir.value(fwd)
                if self.dir_n is not None:
                    self.dir_n.value(1 - fwd)
                self._fwd = fwd
            self.pwm_a.duty_u16(u16)

    def off(self):
        """Motor unpowered. Must not fail: called on every exit and fault path."""
        self.duty = 0
        self.pwm_a.duty_u16(0)
        if self.pwm_b is not None:
            self.pwm_b.duty_u16(0)

    def deinit(self):
        self.off()
        for p in (self.pwm_a, self.pwm_b):
            if p is not None and hasattr(p, "deinit"):
                p.deinit()
