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
from firmware.portable import const, ptr32, word_property, zeros

try:
    import micropython  # @micropython.viper is resolved by MicroPython's compiler
except ImportError:  # CPython
    from firmware import portable as micropython

TWO_PWM = const(0)
PWM_DIR = const(1)

# Motor.st: what set() reads and writes each step
SIGN = const(0)  # +1, or -1 with "motor_invert"
KIND = const(1)  # TWO_PWM or PWM_DIR
FWD = const(2)  # direction last driven (1 forward, 0 reverse); 2 = none yet / after off()
U16 = const(3)  # duty_u16 last written to the driven channel; 65536 = none yet / after off()
DUTY = const(4)  # the signed duty last set
HAS_DIR_N = const(5)  # 1 when a "dir_n" pin is driven as DIR's complement
WORDS = const(6)
_DUTY_MAX = const(10000)  # pi_control.DUTY_MAX as a compile-time constant for viper (tests/firmware/test_copied_constants.py)


class Motor:
    def __init__(self, machine, board):
        pins = board["motor_pins"]
        freq = board.get("pwm_freq", 20000)
        timers = board.get("pwm_timers", {})
        st = zeros(WORDS)
        self.st = st
        st[SIGN] = -1 if board.get("motor_invert") else 1
        self.pwm_b = None
        self.dir = None
        self.dir_n = None
        if board["driver"] == "two_pwm":
            st[KIND] = TWO_PWM
            self.pwm_a = hal.pwm(machine, pins["in1"], freq, timers.get("in1"))
            self.pwm_b = hal.pwm(machine, pins["in2"], freq, timers.get("in2"))
        elif board["driver"] == "pwm_dir":
            st[KIND] = PWM_DIR
            self.pwm_a = hal.pwm(machine, pins["pwm"], freq, timers.get("pwm"))
            self.dir = hal.out_pin(machine, pins["dir"])
            if "dir_n" in pins:
                self.dir_n = hal.out_pin(machine, pins["dir_n"])
                st[HAS_DIR_N] = 1
        else:
            raise ValueError("unknown driver %r (two_pwm or pwm_dir)" % board["driver"])
        self.off()

    duty = word_property(DUTY)
    sign = word_property(SIGN)
    kind = word_property(KIND)

    @micropython.viper
    def set(self, duty: int):
        """Drive with a signed duty; values beyond +-DUTY_MAX are clamped. Allocation-free.
        Writes only what changes: the idle channel is zeroed when the direction changes (and by
        off()), and an unchanged duty is not written again (one C call per step, or none)."""
        s = ptr32(self.st)
        if duty > _DUTY_MAX:
            duty = _DUTY_MAX
        elif duty < -_DUTY_MAX:
            duty = -_DUTY_MAX
        s[DUTY] = duty
        d = duty
        if s[SIGN] != 1:
            d = -duty
        fwd = 1
        if d < 0:
            fwd = 0
            d = -d
        u16 = (d * 65535) // _DUTY_MAX  # <= 655 350 000 < 2**30
        if s[KIND] == TWO_PWM:
            if s[FWD] != fwd:
                # the channel that drove the old direction goes to 0 first
                if fwd:
                    self.pwm_b.duty_u16(0)
                else:
                    self.pwm_a.duty_u16(0)
                s[FWD] = fwd
                s[U16] = 65536  # no duty_u16 value: the next write happens
            if s[U16] != u16:
                if fwd:
                    self.pwm_a.duty_u16(u16)
                else:
                    self.pwm_b.duty_u16(u16)
                s[U16] = u16
        else:
            # Duty to 0 before flipping the direction, so the bridge never drives the old
            # duty the wrong way for a moment.
            if s[FWD] != fwd:
                self.pwm_a.duty_u16(0)
                self.dir.value(fwd)
                if s[HAS_DIR_N]:
                    self.dir_n.value(1 - fwd)
                s[FWD] = fwd
                s[U16] = 65536
            if s[U16] != u16:
                self.pwm_a.duty_u16(u16)
                s[U16] = u16

    def off(self):
        """Motor unpowered. Must not fail: called on every exit and fault path."""
        st = self.st
        st[DUTY] = 0
        st[FWD] = 2  # neither direction: the next set() writes both channels as it needs
        st[U16] = 65536
        self.pwm_a.duty_u16(0)
        if self.pwm_b is not None:
            self.pwm_b.duty_u16(0)

    def deinit(self):
        self.off()
        for p in (self.pwm_a, self.pwm_b):
            if p is not None and hasattr(p, "deinit"):
                p.deinit()
