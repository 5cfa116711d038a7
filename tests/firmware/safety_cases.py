"""Cases of the firmware's safety rules, written once and run under both CPython and MicroPython
(testkit.interpreters: `both("tests.firmware.safety_cases", "case_x(...)")`, from
tests/firmware/test_app_safety.py): a wiper lift, host silence in every motion mode, an exception
in the step and KeyboardInterrupt in run() each stop the motor; stop() turns the bridge off at
once, and board_main.run turns it off whatever escapes the App; every command counts as hearing
the host.

Each case takes plain data (a replay data file written by the CPython test: ADC codes recorded
from the simulated actuator and calibration files made from it, testkit.model) and raises
AssertionError on failure; it returns a small dict of figures that the CPython test also checks.
"""

from testkit.replay import load, pwm_duties, replay_app, run_steps

try:
    import micropython
except ImportError:
    micropython = None


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
