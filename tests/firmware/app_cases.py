"""Cases of the firmware's App, written once and run under both CPython and MicroPython
(testkit.interpreters: `both("tests.firmware.app_cases", "case_x(...)")`).

Each case takes plain data (a replay data file written by the CPython test: ADC codes recorded
from the simulated actuator and calibration files made from it, testkit.model) and raises
AssertionError on failure; it returns a small dict of figures that the CPython test also checks.
"""

import gc
from array import array

from testkit.replay import Pin, ReplayMachine, load, load_calibration, pwm_duties, replay_app, run_steps

try:
    import micropython
except ImportError:
    micropython = None

# Every firmware module (tests/firmware/test_app.py checks this against firmware/*.py).
MODULES = (
    "portable", "hal", "board_config", "sampler", "bcm_fixed", "pwl_fixed", "poly_fixed",
    "calibration", "measurement", "pi_control", "motor", "safety", "telemetry", "controller",
    "protocol", "link", "records", "saved_params", "param_table", "app", "board_main",
)
# ... but these, which import what only one runtime has (run on the emulated CircuitPython Pico
# by tests/link/test_emulated_circuitpython.py)
RUNTIME_ONLY = {"circuitpython_hw": "analogio, pwmio and digitalio: CircuitPython only"}


def case_imports():
    import firmware

    names = []
    for name in MODULES:
        __import__("firmware." + name)
        assert getattr(firmware, name) is not None
        names.append(name)
    return {"modules": names}


def case_heap_lock(path, mode, target, n=10000):
    """n control steps in `mode` with the heap locked: no MemoryError, no allocation."""
    data = load(path)
    app, _ = replay_app(data, calibration="model" if mode in ("position", "force") else None)
    app.set_param("host_timeout_ms", 600000)  # the watchdog runs, but must not stop this run
    app.set_stream(100)
    app.set_mode(mode)
    app.set_target(target)
    run_steps(app.step, 50)  # first calls settle attribute caches outside the lock
    gc.collect()
    before = gc.mem_alloc() if hasattr(gc, "mem_alloc") else 0
    locked = micropython is not None and hasattr(micropython, "heap_lock")
    if locked:
        micropython.heap_lock()
    try:
        run_steps(app.step, n)
    finally:
        if locked:
            micropython.heap_unlock()
    after = gc.mem_alloc() if hasattr(gc, "mem_alloc") else 0
    st = app.status()
    assert st["faults"] == [], st
    assert st["mode"] == mode, st
    from firmware.protocol import STATUS_KEYS

    assert sorted(st) == sorted(STATUS_KEYS), sorted(st)  # the interface table names every key
    assert app.ctrl.steps == n + 50
    if mode != "idle":
        assert app.ctrl.duty != 0, "the loop never drove the motor"
    assert app.telemetry.available() > 0
    cal = app.calibration
    pots = [cal.pot1[0], cal.pot2[0]] if cal is not None else None
    return {"locked": locked, "before": before, "after": after, "duty": app.ctrl.duty, "pots": pots}


def case_rail_fault(path, pot):
    """A wiper lift on `pot` stops the motor within one control period and names the pot."""
    data = load(path)
    app, machine = replay_app(data)
    app.set_mode("open_loop")
    app.set_target(4000)
    run_steps(app.step, 100)
    assert app.ctrl.duty == 4000 and max(pwm_duties(app)) > 0
    pin = app.board["adc_pins"][pot]
    adc = machine.adcs[pin]
    machine.rail(pin, adc.i, 65535)  # every read from the next step on is at the top rail
    app.step(None)
    st = app.status()
    assert pwm_duties(app) == [0, 0], pwm_duties(app)
    assert st["mode"] == "idle" and st["faults"] == ["rail_" + pot], st
    assert pot in st["last_fault"] and "4095" in st["last_fault"], st["last_fault"]
    try:
        app.set_mode("open_loop")
        raise AssertionError("a latched fault must refuse the motor")
    except ValueError as exc:
        assert "reset" in str(exc)
    return {"fault": st["last_fault"]}


def case_host_timeout(path):
    """No command for host_timeout_ms stops the motor; a heartbeat in time keeps it running."""
    data = load(path)
    app, _ = replay_app(data)
    app.set_param("host_timeout_ms", 50)  # 50 steps at 1 kHz
    app.set_mode("position")
    app.set_target(app.ctrl.meas.d2 + 5000)
    run_steps(app.step, 40)
    app.heartbeat()
    run_steps(app.step, 40)
    assert app.status()["mode"] == "position" and app.ctrl.duty != 0
    run_steps(app.step, 9)  # 49 steps of silence
    assert app.status()["mode"] == "position"
    app.step(None)  # the 50th
    st = app.status()
    assert st["mode"] == "idle" and st["faults"] == ["host_timeout"], st
    assert pwm_duties(app) == [0, 0]
    return {"fault": st["last_fault"]}


class BrokenADC:
    def read_u16(self):
        raise OSError(5)  # what a failing peripheral raises on a board


def case_step_exception(path):
    data = load(path)
    app, _ = replay_app(data)
    app.set_mode("open_loop")
    app.set_target(-3000)
    run_steps(app.step, 100)
    assert max(pwm_duties(app)) > 0
    good = app.sampler.adc2
    app.sampler.adc2 = BrokenADC()
    app.step(None)  # must not raise: a hard IRQ cannot propagate it
    st = app.status()
    assert pwm_duties(app) == [0, 0]
    assert st["mode"] == "idle" and "step_exception" in st["faults"], st
    assert "OSError" in st["last_fault"], st["last_fault"]
    text = st["last_fault"]
    # Again as in a hard IRQ, with the heap locked: the failing step still stops the motor
    # (MicroPython may then report MemoryError, as it cannot allocate the OSError itself).
    app.reset()
    app.sampler.adc2 = good
    app.set_mode("open_loop")
    app.set_target(3000)
    run_steps(app.step, 100)
    assert max(pwm_duties(app)) > 0
    app.sampler.adc2 = BrokenADC()
    locked = micropython is not None and hasattr(micropython, "heap_lock")
    if locked:
        micropython.heap_lock()
    try:
        app.step(None)
    finally:
        if locked:
            micropython.heap_unlock()
    st = app.status()
    assert pwm_duties(app) == [0, 0] and st["mode"] == "idle", st
    assert "step_exception" in st["faults"], st
    assert "OSError" in st["last_fault"] or "MemoryError" in st["last_fault"], st["last_fault"]
    return {"fault": text}


class InterruptingLink:
    """Runs the timer like time passing, then Ctrl-C arrives while the motor is driven."""

    def __init__(self, app, ticks):
        self.app = app
        self.ticks = ticks
        self.polls = 0
        self.duty_seen = 0

    def poll(self):
        self.polls += 1
        self.app._timer.fire(10)
        self.app.heartbeat()
        self.duty_seen = max(self.duty_seen, max(pwm_duties(self.app)))
        if self.polls * 10 >= self.ticks:
            raise KeyboardInterrupt


def case_keyboard_interrupt(path):
    data = load(path)
    app, _ = replay_app(data)
    app.set_mode("open_loop")
    app.set_target(5000)
    link = InterruptingLink(app, 200)
    try:
        app.run(link)
        raise AssertionError("run() swallowed KeyboardInterrupt")
    except KeyboardInterrupt:
        pass
    assert link.duty_seen > 0
    assert pwm_duties(app) == [0, 0]
    assert app._timer is None
    st = app.status()
    assert st["mode"] == "idle" and "interrupted" in st["faults"], st
    return {"duty_seen": link.duty_seen}


def case_stop_turns_the_bridge_off(path):
    """Open loop running, then stop(): both PWM outputs 0 at once, without another step."""
    data = load(path)
    app, _ = replay_app(data)
    app.set_mode("open_loop")
    app.set_target(5000)
    run_steps(app.step, 5)
    running = max(pwm_duties(app))
    app.stop()
    assert pwm_duties(app) == [0, 0], pwm_duties(app)
    assert app.ctrl.mode == 0 and app.ctrl.duty == 0
    return {"running": running}


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


def case_board_main_stops_what_run_left_running(path):
    """board_main.run with an App.run that drives the bridge and then raises without its own
    shutdown: the bridge is off when board_main.run has returned (by the exception)."""
    import firmware.app as app_module
    from firmware import board_main

    data = load(path)
    _, machine = replay_app(data, calibration=None)
    seen = {}

    def run_that_escapes(self, link=None):
        self.set_mode("open_loop")
        self.set_target(4000)
        run_steps(self.step, 5)
        seen["app"] = self
        seen["during"] = max(pwm_duties(self))
        raise KeyboardInterrupt

    class QuietLink:  # the real one writes its binary hello to stdout, where this case reports
        def __init__(self, app, stdin=None, write=None):
            pass

        def hello(self):
            pass

    import firmware.link as link_module

    original = app_module.App.run, link_module.Link
    app_module.App.run, link_module.Link = run_that_escapes, QuietLink
    try:
        board_main.run("boards/sim.json", "no-calibration.json", machine=machine, exit_path=None, params_path=None)
        raise AssertionError("board_main.run swallowed the exception")
    except KeyboardInterrupt:
        pass
    finally:
        app_module.App.run, link_module.Link = original
    return {"during": seen["during"], "after": pwm_duties(seen["app"])}


def case_refused_without_calibration(path):
    data = load(path)
    app, _ = replay_app(data, calibration=None)
    for mode in ("position", "force"):
        try:
            app.set_mode(mode)
            raise AssertionError("closed loop accepted without calibration")
        except ValueError as exc:
            assert "calibration" in str(exc), str(exc)
    st = app.status()
    assert st["calibration_crc"] is None and st["calibration_error"], st
    app.set_mode("open_loop")  # raw readings and open loop still work
    app.set_target(2000)
    run_steps(app.step, 100)
    assert app.ctrl.duty == 2000 and app.sampler.raw1 > 0
    # a calibration without the force steps: position works, force is refused with the reason
    app.set_calibration(load_calibration(data, "pots_only"))
    app.set_mode("position")
    try:
        app.set_mode("force")
        raise AssertionError("force mode accepted without a force calibration")
    except ValueError as exc:
        assert "Df" in str(exc) or "force" in str(exc), str(exc)
    return {"error": st["calibration_error"]}


def case_load_force_play(path):
    """The load-force estimate with a calibrated block friction h is a play operator of width h
    on the (low-passed) spring force: it moves only when the spring force leaves the band, and
    `dir` says which edge moved last; deformation_targets put the spring at either edge."""
    from firmware.measurement import Measurement

    data = load(path)
    cal = load_calibration(data)
    h = cal.friction[0]
    m = Measurement(cal)
    seen = []
    for spring, expect in ((0, 0), (5000, 5000 - h), (4900, 5000 - h), (4000, 4000 + h), (4500, 4000 + h),
                           (-3000, -3000 + h), (-2800, -3000 + h), (-2000, -2000 - h)):
        i = 0
        while i < 800:  # the 64-step low-pass settles to within 1 mN of a 5 N step in ~550 steps
            out = m._load_force(spring)
            i += 1
        assert abs(out - expect) <= 2, (spring, out, expect)
        seen.append([out, m.dir])
    assert [d for _, d in seen] == [0, -1, -1, 1, 1, 1, 1, -1], seen
    targets = array("i", [0, 0, 0])
    m.deformation_targets(-5000, targets)
    assert targets[2] < targets[1] < targets[0], list(targets)  # s = +1 works from the lower edge
    assert targets[1] == m.deformation_for(-5000)
    assert targets[2] == m.deformation_for(-5000 - h) and targets[0] == m.deformation_for(-5000 + h)
    return {"seen": seen, "targets": list(targets)}


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


def case_ring():
    from firmware.telemetry import RECORD_WORDS, Ring

    r = Ring(4)
    r.every = 1
    dst = array("i", [0] * RECORD_WORDS)
    assert not r.read_into(dst)
    rec = array("i", [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, -11])  # a negative word comes back as it went
    i = 0
    while i < 6:
        rec[0] = i
        assert r.push(rec)
        i += 1
    got = []
    while r.read_into(dst):
        got.append(dst[0])
        assert list(dst[1:]) == list(range(1, 11)) + [-11]
    assert got == [2, 3, 4, 5] and r.dropped == 2, (got, r.dropped)
    r.every = 3
    kept = [r.push(rec) for _ in range(9)]
    assert kept == [False, False, True] * 3, kept
    return {"dropped": r.dropped}


def case_board_files():
    """Every shipped board file loads; broken ones fail with a reason a user can act on."""
    from firmware.board_config import BoardError, check_board, load_board

    names = []
    for name in ("pico", "esp32_devkitc", "pyboard", "sim"):
        b = load_board("boards/%s.json" % name)
        assert b["loop_hz"] == 1000 and b["adc_bits"] == 12 and b["sources"], name
        names.append(b["name"])
    reasons = []
    for broken in (
        {"name": "x", "adc_bits": 12, "adc_pins": {"pot1": 1}, "driver": "two_pwm", "motor_pins": {"in1": 2, "in2": 3}},
        {"name": "x", "adc_bits": 12, "adc_pins": {"pot1": 1, "pot2": 2}, "driver": "l298", "motor_pins": {}},
        {"name": "x", "adc_bits": 12, "adc_pins": {"pot1": 1, "pot2": 2}, "driver": "pwm_dir", "motor_pins": {"pwm": 4}},
        {"name": "x", "adc_bits": 24, "adc_pins": {"pot1": 1, "pot2": 2}, "driver": "two_pwm", "motor_pins": {"in1": 2, "in2": 3}},
    ):
        try:
            check_board(broken)
            raise AssertionError("accepted a broken board %r" % broken)
        except BoardError as exc:
            reasons.append(str(exc))
    assert "pot2" in reasons[0] and "l298" in reasons[1] and "dir" in reasons[2] and "adc_bits" in reasons[3], reasons
    try:
        load_board("boards/no_such_board.json")
        raise AssertionError("missing board file accepted")
    except BoardError as exc:
        assert "not found" in str(exc)
    return {"boards": names, "reasons": reasons}


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


def case_watchdog_in_every_motion_mode(path):
    """host_timeout_ms of silence stops the motor in open loop, position and force alike (the
    guided sweeps run in open loop); idle counts the silence but has nothing to stop."""
    data = load(path)
    out = {}
    for mode, target in (("open_loop", 3000), ("position", None), ("force", 3000)):
        app, _ = replay_app(data)
        app.set_param("host_timeout_ms", 50)  # 50 steps at 1 kHz
        app.set_mode(mode)
        app.set_target(app.ctrl.meas.d2 + 5000 if target is None else target)
        run_steps(app.step, 49)
        assert app.status()["mode"] == mode, (mode, app.status())
        app.step(None)
        st = app.status()
        assert st["mode"] == "idle" and st["faults"] == ["host_timeout"], (mode, st)
        assert pwm_duties(app) == [0, 0], mode
        out[mode] = st["faults"]
    app, _ = replay_app(data)
    app.set_param("host_timeout_ms", 50)
    run_steps(app.step, 80)
    assert app.status()["faults"] == [] and app.safety.silence == 80
    return out


def case_commands_count_as_hearing_the_host(path):
    """Every command resets the watchdog: a host that only sends targets (or reads a parameter)
    more often than host_timeout_ms keeps the motor running."""
    data = load(path)
    out = {}
    for name in ("set_target", "get_param", "heartbeat", "set_mode"):
        app, _ = replay_app(data)
        app.set_param("host_timeout_ms", 50)
        app.set_mode("open_loop")
        app.set_target(2000)
        i = 0
        while i < 10:
            run_steps(app.step, 40)
            if name == "set_target":
                app.set_target(2000)
            elif name == "get_param":
                app.get_param("slew")
            elif name == "heartbeat":
                app.heartbeat()
            else:
                app.set_mode("open_loop")
                app.set_target(2000)
            i += 1
        st = app.status()
        assert st["faults"] == [] and st["mode"] == "open_loop", (name, st)
        out[name] = st["steps"]
    return out


def case_range_checks(path):
    """Targets and parameters outside their ranges are refused with ValueError and change
    nothing: position +-65535 um, open-loop duty +-10000, force +-200 N, every parameter's own
    min..max from the table."""
    from firmware.protocol import PARAMS

    data = load(path)
    app, _ = replay_app(data)
    refused = []

    def refuse(f, *a):
        try:
            f(*a)
        except ValueError:
            refused.append(1)
            return
        raise AssertionError("accepted %r" % (a,))

    app.set_mode("position")
    before = app.ctrl.target
    refuse(app.set_target, 65536)
    refuse(app.set_target, -65536)
    assert app.ctrl.target == before
    app.set_mode("open_loop")
    refuse(app.set_target, 10001)
    refuse(app.set_target, -10001)
    app.set_mode("force")
    before = app.ctrl.target
    refuse(app.set_target, 200001)
    refuse(app.set_target, -200001)
    assert app.ctrl.target == before
    for name, default, lo, hi, _ in PARAMS:
        refuse(app.set_param, name, lo - 1)
        refuse(app.set_param, name, hi + 1)
        assert app.get_param(name) == default, name
    return {"refused": len(refused)}


def case_host_silence_restores_params(path):
    """A host that opened the stroke limits, started a sweep and went silent: the watchdog stops
    the motor and every parameter is back at its boot value (App.watch_host, which run() calls
    each pass); status shows the limits in force. A host heard in time, or one quiet while the
    board is idle, keeps its settings."""
    data = load(path)
    app, _ = replay_app(data)
    boot = app.status()["stroke_um"]
    app.set_param("stroke_min_um", -65535)
    app.set_param("stroke_max_um", 65535)
    app.set_param("host_timeout_ms", 50)
    st = app.status()
    assert st["stroke_um"] == [-65535, 65535] and "host_timeout_ms" in st["params_changed"], st
    i = 0
    while i < 300:  # idle and quiet: nothing to stop, nothing comes back
        app.step(None)
        assert not app.watch_host()
        i += 1
    app.set_mode("open_loop")
    app.set_target(1500)
    i = 0
    while i < 300:  # moving, heard every 40 steps: nothing comes back
        app.step(None)
        assert not app.watch_host()
        if i % 40 == 0:
            app.heartbeat()
        i += 1
    assert app.status()["stroke_um"] == [-65535, 65535] and app.status()["mode"] == "open_loop"
    app.heartbeat()  # the host's last word
    restored_at = None
    i = 0
    while i < 120:  # silent: the watchdog trips after 50 steps and the parameters come back
        app.step(None)
        if app.watch_host():
            restored_at = i + 1
        i += 1
    st = app.status()
    assert restored_at == 50, restored_at
    assert st["faults"] == ["host_timeout"] and st["stroke_um"] == boot and st["params_changed"] == [], st
    assert app.get_param("host_timeout_ms") == 1000
    assert "stroke_min_um" in st["params_restored"], st
    # the same through run(), as a board's main loop runs it: a link that only lets time pass
    app.reset()
    app.set_param("stroke_max_um", 65535)
    app.set_mode("open_loop")
    app.set_target(1500)

    class SilentLink:
        polls = 0

        def poll(self):  # one main-loop pass = 10 steps of the timer
            run_steps(app.step, 10)
            SilentLink.polls += 1
            if SilentLink.polls == 150:
                app.quit()

    app.run(SilentLink())
    assert app.status()["stroke_um"] == boot, app.status()
    return {"restored_at": restored_at, "stroke_um": st["stroke_um"]}


def case_boot_survives_any_calibration(path, bad_paths):
    """Every file in bad_paths as the calibration: the App boots, motor off, no calibration,
    and says why; open loop still works."""
    from firmware.app import App

    whys = []
    for bad in bad_paths:
        app = App("boards/sim.json", bad, machine=ReplayMachine({"pot1": [32000], "pot2": [32000], "reference": [32000], "gauge": [32000]}))
        st = app.status()
        assert st["calibration_crc"] is None and st["calibration_error"], st
        assert pwm_duties(app) == [0, 0]
        app.set_mode("open_loop")
        app.set_target(1000)
        whys.append(st["calibration_error"])
    return {"why": whys}


def case_calibrations_the_board_refuses(path):
    """A pot table whose positions fall as the code rises, and a calibration made for another
    board: both refused with the reason; closed loop refused, open loop still works."""
    data = load(path)
    app, _ = replay_app(data)
    whys = []
    for cal in (load_calibration(data, "falling"), load_calibration(data, "other_board")):
        app.set_calibration(cal)
        st = app.status()
        assert st["calibration_crc"] is None and st["calibration_error"], st
        try:
            app.set_mode("position")
            raise AssertionError("closed loop accepted")
        except ValueError:
            pass
        app.set_mode("open_loop")
        app.set_mode("idle")
        whys.append(st["calibration_error"])
    assert "falls" in whys[0] and "pico" in whys[1], whys
    return {"why": whys}


def case_stroke_limits_from_end_stops(path):
    """The soft limits in force: the parameters, kept stop_margin_um inside the end stops the
    calibration measured (its stroke section); a negative margin (calibration sweeps) lets the
    parameters alone decide; without end stops the parameters alone decide."""
    data = load(path)
    app, _ = replay_app(data)
    out = {"none": app.status()["stroke_um"], "stops_none": app.status()["end_stops_um"]}
    for name, stops in (("low_shifted", [-2000, 58000]), ("high_shifted", [1000, 61000])):
        app.set_calibration(load_calibration(data, "stroke_" + name))  # end stops at `stops`
        st = app.status()
        assert st["calibration_error"] is None and st["end_stops_um"] == stops, st
        out[name] = st["stroke_um"]
    app.set_param("stroke_min_um", 2000)  # a parameter inside the stops wins
    out["param_inside"] = app.status()["stroke_um"]
    app.set_param("stop_margin_um", -65535)  # a sweep opens them to the parameters
    out["margin_open"] = app.status()["stroke_um"]
    app.set_param("stroke_min_um", -65535)
    app.set_param("stroke_max_um", 65535)
    out["all_open"] = app.status()["stroke_um"]
    app.set_calibration(load_calibration(data))  # a calibration without end stops forgets them
    out["forgotten"] = app.status()["end_stops_um"]
    return out


def case_calibrations_for_another_adc_width(path, bcm3_path):
    """Pot constants exported for another ADC width than the board's are refused with the reason
    before any curve is evaluated: a 10-bit table, and a bcm3 with input shift 0, which declares
    29 bits (the boot would evaluate all 2**29 codes first: hours on a Cortex-M0, the board
    silent meanwhile). Open loop still works."""
    data = load(path)
    whys = []
    narrow = load_calibration(data, "narrow")  # pwl tables with input shift 6: a 10-bit ADC
    wide = load_calibration(load(bcm3_path), "wide")  # bcm3 with input shift 0: a 29-bit ADC
    assert narrow.pot1[0] == "pwl" and narrow.pot1[1][1] == 6 and wide.pot1[0] == "bcm3" and wide.pot1[1][0] == 0
    from firmware.bcm_fixed import invalid

    assert invalid(wide.pot1[1]) is None  # still a valid bcm3 layout
    app, _ = replay_app(data)
    for cal in (narrow, wide):
        app.set_calibration(cal)
        st = app.status()
        assert st["calibration_crc"] is None, st
        whys.append(st["calibration_error"])
        app.set_mode("open_loop")
        app.set_mode("idle")
    assert "10-bit ADC" in whys[0] and "29-bit ADC" in whys[1] and "12-bit" in whys[1], whys
    return {"why": whys}


def case_temporary_params_come_back_when_the_host_goes_silent(path):
    """Values a host command sets as temporary (the stroke limits a sweep opens, the gains a
    tuning run tries) go back to what they were before once the host has been silent for
    host_timeout_ms, with the motor off too (a host killed between two sweeps); values set for
    good stay; a plain set ends a temporary value; after a watchdog trip the boot values come
    back once, and what the host sets afterwards stays."""
    data = load(path)
    app, _ = replay_app(data)
    boot = app.status()["stroke_um"]
    app.set_param("host_timeout_ms", 50)  # for good: 50 steps at 1 kHz
    app.set_param("kp_pos", 900)
    app.set_param("stroke_min_um", -65535, temporary=True)
    app.set_param("stroke_max_um", 65535, temporary=True)
    app.set_param("kp_pos", 5000, temporary=True)
    app.set_param("kp_pos", 6000, temporary=True)  # still temporary; 900 is what comes back
    st = app.status()
    assert st["params_temporary"] == ["kp_pos", "stroke_min_um", "stroke_max_um"], st
    assert st["stroke_um"] == [-65535, 65535]

    def idle_steps(n):
        """Steps until the parameters came back (its number), or None after n."""
        i = 0
        while i < n:
            app.step(None)
            if app.watch_host():
                return i + 1
            i += 1
        return None

    assert idle_steps(40) is None
    app.heartbeat()  # heard: the silence starts again
    assert idle_steps(40) is None
    app.heartbeat()
    restored_at = idle_steps(120)
    st = app.status()
    assert restored_at == 50, restored_at
    assert st["stroke_um"] == boot and st["params_temporary"] == [] and st["mode"] == "idle", st
    assert app.get_param("kp_pos") == 900 and app.get_param("host_timeout_ms") == 50
    assert "stroke_min_um" in st["params_restored"] and "temporary" in st["params_restored"], st
    assert idle_steps(200) is None  # nothing left to restore
    # a plain set ends a temporary value: it stays
    app.set_param("stroke_max_um", 65535, temporary=True)
    app.set_param("stroke_max_um", 60000)
    assert app.status()["params_temporary"] == []
    assert idle_steps(200) is None and app.get_param("stroke_max_um") == 60000
    # a watchdog trip in a motion: every parameter back to boot values, once
    app.set_param("slew", 400, temporary=True)
    app.set_mode("open_loop")
    app.set_target(1500)
    tripped_at = idle_steps(120)
    st = app.status()
    assert tripped_at == 50 and st["faults"] == ["host_timeout"] and st["params_temporary"] == [], (tripped_at, st)
    from firmware.protocol import PARAMS

    default = dict((row[0], row[1]) for row in PARAMS)
    assert app.get_param("kp_pos") == default["kp_pos"] and app.get_param("slew") == default["slew"], st
    assert st["stroke_um"] == boot
    app.set_param("kp_pos", 1000)  # the host is back and sets a gain before any reset: it stays
    assert idle_steps(100) is None and app.get_param("kp_pos") == 1000
    return {"restored_at": restored_at, "tripped_at": tripped_at}


def case_df_table(path, codes):
    """D1* of pot 1's codes with the calibration file at `path`, whose Df is a table (df_kind pwl):
    [D1*, D1] per code, as the board's per-code table holds them."""
    from firmware.calibration import load_calibration as load_file
    from firmware.measurement import Measurement

    m = Measurement(load_file(path))
    return [[m._d1(m.conv1(c, m.k1)), m.conv1(c, m.k1)] for c in codes]


def case_stroke_limits_must_leave_a_stroke(path, params_path, junk_path):
    """stroke_min_um must stay below stroke_max_um: set_param refuses a value that would cross the
    other (each alone is within its range), and a saved file with such a pair is refused whole at
    boot with the reason, the defaults standing. A params file of random bytes is refused with a
    reason that says something."""
    from firmware import saved_params
    from firmware.app import App
    from firmware.hal import record
    from firmware.protocol import PARAMS

    data = load(path)
    app, machine = replay_app(data)
    refused = []
    for name, value in (("stroke_min_um", 59500), ("stroke_min_um", 60000), ("stroke_max_um", 500), ("stroke_max_um", -100)):
        try:
            app.set_param(name, value)
        except ValueError as exc:
            refused.append(str(exc))
            continue
        raise AssertionError("accepted %s=%d" % (name, value))
    assert app.status()["stroke_um"] == [500, 59500], app.status()["stroke_um"]
    app.set_param("stroke_min_um", -65535)  # opening both, min first, is fine
    app.set_param("stroke_max_um", 65535)
    values = [row[1] for row in PARAMS]
    values[[row[0] for row in PARAMS].index("stroke_min_um")] = 40000
    values[[row[0] for row in PARAMS].index("stroke_max_um")] = 30000
    saved_params.save(record(params_path), PARAMS, values)
    booted = App("boards/sim.json", None, machine=machine, params_record=record(params_path))
    junk = App("boards/sim.json", None, machine=machine, params_record=record(junk_path))
    return {"refused": len(refused), "first": refused[0], "file_error": booted.status()["params_file_error"],
            "stroke": booted.status()["stroke_um"], "junk_error": junk.status()["params_file_error"]}
