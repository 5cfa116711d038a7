"""Cases of the drive path, from the control loop's output to the bridge's pins, written once and
run under both CPython and MicroPython (testkit.interpreters:
`both("tests.firmware.drive_cases", "case_x(...)")`, from tests/firmware/test_drive.py; some
also from the mpy-cross compiled firmware, tests/firmware/test_mpy.py): the motor's clamp, the
position loop's output clamp with the feed-forward, the slew limit, the PI's anti-windup, both
bridge wirings and the pyboard's pyb.Timer PWM adapter.

Each case takes plain data (a replay data file written by the CPython test: ADC codes recorded
from the simulated actuator and calibration files made from it, testkit.model), or none, and
raises AssertionError on failure; it returns a small dict of figures that the CPython test also
checks.
"""

from testkit.replay import Pin, ReplayMachine, load, pwm_duties, replay_app, run_steps


def case_motor_clamps(path):
    """motor.set beyond +-DUTY_MAX: the duty kept and the PWM written are full scale, no more."""
    data = load(path)
    app, _ = replay_app(data)
    duty, u16 = [], []
    for asked in (20000, -20000):
        app.motor.set(asked)
        duty.append(app.motor.duty)
        u16.append(max(pwm_duties(app)))
    app.motor.off()
    return {"duty": duty, "u16": u16}


def case_position_output_clamp(path, ff_path):
    """Position mode far from the target both ways with a feed-forward calibration and a small
    out_limit: the duty the step writes is exactly +-out_limit (PI saturated, feed-forward added,
    then clamped)."""
    from firmware.calibration import load_calibration as load_file

    data = load(path)
    app, _ = replay_app(data, calibration=None)
    app.set_calibration(load_file(ff_path))
    limit = 3000
    app.set_param("out_limit", limit)
    app.set_mode("position")
    duty = []
    for target in (65000, -65000):  # beyond either soft limit: the error stays large
        app.set_target(target)
        run_steps(app.step, 30)
        duty.append(app.ctrl.duty)
    app.stop()
    from firmware.measurement import FF_DUTY

    ff_duty = app.ctrl.meas.st[FF_DUTY]
    return {"duty": duty, "out_limit": limit, "ff_duty": ff_duty}


def case_slew(path):
    """Open-loop step 0 -> +10000 -> -10000: the duty moves at most `slew` per step."""
    data = load(path)
    app, _ = replay_app(data)
    app.set_param("slew", 37)
    app.set_param("stroke_min_um", -65535)  # this case is about the slew limit alone
    app.set_param("stroke_max_um", 65535)
    app.set_mode("open_loop")
    app.set_target(10000)
    prev = 0
    steps = 0
    while app.ctrl.duty != 10000:
        app.step(None)
        assert abs(app.ctrl.duty - prev) <= 37
        prev = app.ctrl.duty
        steps += 1
        assert steps < 1000
    app.set_target(-10000)
    while app.ctrl.duty != -10000:
        app.step(None)
        assert abs(app.ctrl.duty - prev) <= 37
        prev = app.ctrl.duty
        steps += 1
        assert steps < 2000
    assert pwm_duties(app) == [0, 65535]
    return {"steps": steps}


def case_anti_windup():
    """PI saturated for 5 s: the integral stays bounded (none while saturated) and the output
    leaves the limit on the first step the error changes sign; a PI without anti-windup would
    take ~int_limit worth of steps."""
    from firmware.pi_control import PI

    pi = PI()
    kp, ki, out_limit, int_limit = 256, 64, 3000, 2000
    pi.update(20, kp, ki, out_limit, int_limit)  # a small error first: some integral builds
    integ0 = pi.integ
    i = 0
    while i < 5000:
        u = pi.update(30000, kp, ki, out_limit, int_limit)
        assert u == out_limit
        assert abs(pi.integ) <= int_limit << 8
        i += 1
    assert pi.integ == integ0, (pi.integ, integ0)  # no integration while saturated
    u = pi.update(-20, kp, ki, out_limit, int_limit)
    assert u < 0, u  # recovers at once: no wound-up integral to unwind
    # without saturation the integral does accumulate, and is clamped
    pi.reset()
    i = 0
    while i < 20000:
        pi.update(1000, 0, ki, out_limit, int_limit)
        i += 1
    assert pi.integ == int_limit << 8
    return {"integ": pi.integ}


def case_motor_wiring():
    """two_pwm (pico, DRV8833) and pwm_dir (esp32, TB6612) map a signed duty to the pins."""
    from firmware.board_config import load_board
    from firmware.motor import Motor

    out = {}
    b = load_board("boards/pico.json")
    m = Motor(ReplayMachine({}), b)
    m.set(2500)
    assert (m.pwm_a.duty_u16(), m.pwm_b.duty_u16()) == (16383, 0)
    m.set(-10000)
    assert (m.pwm_a.duty_u16(), m.pwm_b.duty_u16()) == (0, 65535)
    m.off()
    assert (m.pwm_a.duty_u16(), m.pwm_b.duty_u16()) == (0, 0)
    b = load_board("boards/esp32_devkitc.json")
    m = Motor(ReplayMachine({}), b)
    m.set(5000)
    assert (m.pwm_a.duty_u16(), m.dir.value(), m.dir_n.value()) == (32767, 1, 0)
    m.set(-5000)
    assert (m.pwm_a.duty_u16(), m.dir.value(), m.dir_n.value()) == (32767, 0, 1)
    m.set(20000)  # clamped
    assert m.pwm_a.duty_u16() == 65535 and m.duty == 10000
    m.off()
    assert m.pwm_a.duty_u16() == 0
    out["ok"] = True
    return out


class _PybTimer:
    """The part of pyb.Timer the pyboard PWM adapter uses (168 MHz TIM8 at `freq`)."""

    PWM = 2

    def __init__(self, id, freq):
        self.id = id
        self._period = 168000000 // freq - 1

    def period(self):
        return self._period

    def channel(self, n, mode, pin=None, pulse_width=0):
        ch = _PybChannel(n, pin, pulse_width)
        _PYB.channels[(self.id, n)] = ch
        return ch


class _PybChannel:
    def __init__(self, n, pin, pulse_width):
        self.n = n
        self.pin = pin
        self.pw = pulse_width

    def pulse_width(self, v):
        self.pw = v


class _PYB:
    Timer = _PybTimer
    Pin = Pin
    channels = {}


def case_pyboard_pwm_adapter():
    """The pyboard board file drives the DRV8833 through pyb.Timer channels (no machine.PWM on
    stm32): duty maps to pulse widths on TIM8 CH1/CH2 of Y1/Y2."""
    import sys

    from firmware.board_config import load_board
    from firmware.motor import Motor

    sys.modules["pyb"] = _PYB
    try:
        m = Motor(ReplayMachine({}), load_board("boards/pyboard.json"))
        ch1 = _PYB.channels[(8, 1)]
        ch2 = _PYB.channels[(8, 2)]
        assert ch1.pin.id == "Y1" and ch2.pin.id == "Y2"
        m.set(5000)
        assert (ch1.pw, ch2.pw) == (4199, 0), (ch1.pw, ch2.pw)  # half of period 8400
        m.set(-10000)
        assert (ch1.pw, ch2.pw) == (0, 8399), (ch1.pw, ch2.pw)
        m.off()
        assert (ch1.pw, ch2.pw) == (0, 0)
    finally:
        del sys.modules["pyb"]
    return {"ok": True}
