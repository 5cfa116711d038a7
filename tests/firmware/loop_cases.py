"""Firmware cases for the loop timer per board file, run under CPython and the real MicroPython.

Same pattern as app_cases.py: each case takes plain data, raises AssertionError on failure
and returns a small JSON-able dict that the CPython test compares across the two interpreters.
The hardware is a stand-in that records how the firmware calls it: which Timer constructor (a
`machine.Timer` or the stm32 `pyb.Timer`), with which id, and whether `hard=True` was asked.
"""

import sys

from testkit.replay import Pin, ReplayMachine, load, pwm_duties, replay_app

BOARDS = ("pico", "esp32_devkitc", "pyboard", "sim")


class _Log:
    calls = []


def _kwargs(kw, callback):
    """kwargs as a sorted JSON-able list; the callback shown as whether it is the App's step."""
    out = []
    for key in sorted(kw):
        v = kw[key]
        if key == "callback":
            v = "step" if v is callback else "other"
        out.append([key, v])
    return out


class RecordingTimer:
    """machine.Timer as the ports have it. `refuse_hard` = the exception a port raises for
    hard=True (rp2 before 1.26: TypeError, an unknown keyword; esp32: ValueError)."""

    PERIODIC = 1
    ONE_SHOT = 0
    refuse_hard = None
    step = None

    def __init__(self, id=-1):
        self.id = id
        self.callback = None
        self.deinited = 0
        _Log.calls.append(["machine.Timer", id])

    def init(self, **kw):
        _Log.calls.append(["init", _kwargs(kw, RecordingTimer.step)])
        if kw.get("hard") and RecordingTimer.refuse_hard is not None:
            raise RecordingTimer.refuse_hard("hard Timers are not implemented")
        self.callback = kw["callback"]

    def deinit(self):
        self.deinited += 1


class RecordingMachine(ReplayMachine):
    Timer = RecordingTimer


class _PybTimer:
    """pyb.Timer: PWM channels for the bridge (as drive_cases._PybTimer) and the loop timer."""

    PWM = 2

    def __init__(self, id, **kw):
        self.id = id
        self.callback = kw.get("callback")
        self.deinited = 0
        self._period = 84000000 // kw.get("freq", 1) - 1
        _Log.calls.append(["pyb.Timer", id, _kwargs(kw, RecordingTimer.step)])

    def period(self):
        return self._period

    def channel(self, n, mode, pin=None, pulse_width=0):
        return _PybChannel()

    def deinit(self):
        self.deinited += 1


class _PybChannel:
    def pulse_width(self, v):
        pass


class _PYB:
    Timer = _PybTimer
    Pin = Pin


def _app(name, refuse_hard=None):
    import json

    from firmware.app import App

    path = "boards/%s.json" % name
    with open(path) as f:
        board = json.load(f)
    codes = {}
    for pin in board["adc_pins"].values():
        codes[pin] = [2048 << 4]
    RecordingTimer.refuse_hard = refuse_hard
    machine = RecordingMachine(codes)
    return App(path, None, machine=machine), machine


def case_loop_timer(name, refuse_hard=None):
    """Boot board `name` on the recording hardware, start the loop, fire one tick, shut down.
    Returns the timer calls the firmware made (loop timer only) and the kind status() reports."""
    refuse = {None: None, "TypeError": TypeError, "ValueError": ValueError}[refuse_hard]
    sys.modules["pyb"] = _PYB
    try:
        app, _ = _app(name, refuse)
        promised = app.status()["timer"]
        RecordingTimer.step = app.step
        _Log.calls = []
        app.start()
        calls = _Log.calls
        tim = app._timer
        assert tim.callback is app.step, "the loop timer must call the App's step"
        steps = app.ctrl.steps
        tim.callback(tim)  # one tick, as the interrupt would call it
        assert app.ctrl.steps == steps + 1
        kind = app.status()["timer"]
        app.shutdown()
        assert tim.deinited == 1 and app._timer is None
    finally:
        del sys.modules["pyb"]
        RecordingTimer.refuse_hard = None
        RecordingTimer.step = None
    return {"calls": calls, "promised": promised, "timer": kind}


def case_loop_hz_checks():
    """loop_hz must be a whole number of the board timer's ticks and of microseconds; broken
    timer keys are refused with the reason."""
    from firmware.board_config import BoardError, check_board, load_board

    def board(**kw):
        b = {"name": "x", "adc_bits": 12, "adc_pins": {"pot1": 1, "pot2": 2}, "driver": "two_pwm",
             "motor_pins": {"in1": 3, "in2": 4}}
        b.update(kw)
        return b

    accepted = []
    for kw in (
        {"loop_hz": 1000},  # the 1 ms soft timer (the default tick)
        {"loop_hz": 500},
        {"loop_hz": 2000, "timer_tick_hz": 1000000},  # rp2's microsecond alarms
        {"loop_hz": 400, "timer_tick_hz": 10000000},  # esp32 80 MHz / 8
        {"loop_hz": 2500, "timer_api": "pyb", "timer_id": 4, "timer_tick_hz": 84000000},
        {"loop_hz": 2000, "simulated": True},  # the sim's timer counts microseconds
    ):
        b = check_board(board(**kw))
        accepted.append([b["loop_hz"], b["timer_tick_hz"], b["timer_api"]])
    reasons = []
    for kw in (
        {"loop_hz": 2000},  # a 1 ms timer cannot tick every 0.5 ms
        {"loop_hz": 400},  # nor every 2.5 ms
        {"loop_hz": 1500, "timer_tick_hz": 84000000},  # the timer could, the us clock cannot
        {"loop_hz": 3000, "timer_tick_hz": 10000000},  # 10 MHz / 3000 is not whole
        {"timer_api": "rtos"},
        {"timer_api": "pyb"},  # no timer number
        {"timer_api": "pyb", "timer_id": 4, "timer_hard": False},
        {"timer_hard": "yes"},
        {"timer_tick_hz": 0},
    ):
        try:
            check_board(board(**kw))
            raise AssertionError("accepted %r" % (kw,))
        except BoardError as exc:
            reasons.append(str(exc))
    assert "loop_hz 2000" in reasons[0] and "timer_tick_hz" in reasons[0] and "1000 Hz" in reasons[0], reasons[0]
    assert "loop_hz 400" in reasons[1] and "divides 1000" in reasons[1], reasons[1]
    assert "1500" in reasons[2] and "1000000" in reasons[2] and "microsecond" in reasons[2], reasons[2]
    assert "3000" in reasons[3] and "10000000 Hz" in reasons[3], reasons[3]
    assert "timer_api" in reasons[4] and "rtos" in reasons[4], reasons[4]
    assert "timer_id" in reasons[5], reasons[5]
    assert "timer_hard" in reasons[6] and "pyb" in reasons[6], reasons[6]
    assert "timer_hard" in reasons[7], reasons[7]
    assert "timer_tick_hz" in reasons[8], reasons[8]
    shipped = []
    for name in BOARDS:
        b = load_board("boards/%s.json" % name)
        assert b["timer_tick_hz"] % b["loop_hz"] == 0
        shipped.append([name, b["timer_api"], b["timer_tick_hz"]])
    return {"accepted": accepted, "reasons": reasons, "shipped": shipped}


# --- why run() ended: recorded after the motor is off, readable at the next boot -------------


def _soft_reset():
    """What machine.soft_reset() does on a board (and on the unix port): raise SystemExit."""
    try:
        import machine
    except ImportError:  # CPython: no machine module
        raise SystemExit
    machine.soft_reset()


class ExitingLink:
    """Polled by run(): fires the timer like time passing while the motor is driven, then ends
    run() the way `how` says; it also reads the exit file while run() is running."""

    def __init__(self, app, how, exit_path, polls=20):
        self.app = app
        self.how = how
        self.exit_path = exit_path
        self.polls = 0
        self.last = polls
        self.duty_seen = 0
        self.while_running = None

    def poll(self):
        self.polls += 1
        if self.polls == 1:
            with open(self.exit_path) as f:
                self.while_running = f.read()
        self.app._timer.fire(10)
        self.app.heartbeat()
        self.duty_seen = max(self.duty_seen, max(pwm_duties(self.app)))
        if self.polls < self.last:
            return
        if self.how == "ctrl_c":
            raise KeyboardInterrupt
        if self.how == "soft_reset":
            _soft_reset()
        if self.how == "exception":
            raise OSError(5)
        self.app.quit()


EXIT_EXPECT = {
    # how: (exception run() must re-raise, fault latched, start of the recorded cause)
    "ctrl_c": (KeyboardInterrupt, "interrupted", "interrupted: KeyboardInterrupt (Ctrl-C)"),
    "soft_reset": (SystemExit, "soft_reset", "soft_reset: SystemExit"),
    "exception": (OSError, "run_exception", "run_exception: OSError"),
    "quit": (None, None, "returned: run() ended normally"),
}


def case_exit_cause(path, exit_path, how):
    """run() driving the motor ends by `how`: the motor is off, the cause is in status() and in
    the exit file, and an App booted afterwards (the next boot) reports it as last_exit."""
    import os

    from firmware.app import EXIT_RUNNING

    try:
        os.remove(exit_path)
    except OSError:
        pass
    data = load(path)
    app, _ = replay_app(data, exit_path=exit_path)
    assert app.status()["last_exit"] is None  # the first boot: nothing recorded yet
    app.set_mode("open_loop")
    app.set_target(5000)
    link = ExitingLink(app, how, exit_path)
    expect_exc, fault, prefix = EXIT_EXPECT[how]
    raised = None
    try:
        app.run(link)
    except BaseException as exc:  # noqa: B036 - SystemExit and KeyboardInterrupt are the point
        raised = exc
    if expect_exc is None:
        assert raised is None, repr(raised)
    else:
        assert isinstance(raised, expect_exc), repr(raised)  # re-raised for the REPL / reset
    assert link.duty_seen > 0 and link.while_running == EXIT_RUNNING, link.while_running
    assert pwm_duties(app) == [0, 0] and app._timer is None
    st = app.status()
    assert st["mode"] == "idle" and st["duty"] == 0, st
    assert st["faults"] == ([fault] if fault else []), st
    text = st["last_exit"]
    assert text.startswith(prefix) and text.endswith("after 200 steps, motor off"), text
    with open(exit_path) as f:
        assert f.read() == text
    # the next boot (a new App on the same flash) reads it back
    again, _ = replay_app(data, exit_path=exit_path)
    st2 = again.status()
    assert st2["last_exit"] == text and st2["faults"] == [] and st2["mode"] == "idle", st2
    return {"exit": text.split(":")[0], "tail": text[-28:], "faults": st["faults"],
            "raised": type(raised).__name__ if raised is not None else None}


def case_exit_unrecorded(path, exit_path):
    """A run() that never reaches its finally (power loss, hard reset) leaves the running marker,
    and the next boot says so rather than repeating an older cause."""
    from firmware.app import EXIT_RUNNING

    data = load(path)
    with open(exit_path, "w") as f:
        f.write("interrupted: KeyboardInterrupt (Ctrl-C) after 7 steps, motor off")
    app, _ = replay_app(data, exit_path=exit_path)
    assert app.status()["last_exit"].startswith("interrupted")
    app._write_exit(EXIT_RUNNING)  # what run() writes first; then the power goes
    again, _ = replay_app(data, exit_path=exit_path)
    assert again.status()["last_exit"] == EXIT_RUNNING
    # no exit file configured (tests, a read-only flash): nothing written, status still has it
    bare, _ = replay_app(data)
    bare.set_mode("open_loop")
    bare.set_target(2000)
    try:
        bare.run(ExitingLink(bare, "ctrl_c", exit_path, polls=3))
    except KeyboardInterrupt:
        pass
    assert bare.status()["last_exit"].startswith("interrupted")
    return {"marker": EXIT_RUNNING}
