"""Cases of the App's parameters and targets, written once and run under both CPython and
MicroPython (testkit.interpreters: `both("tests.firmware.param_cases", "case_x(...)")`, from
tests/firmware/test_params_on_both.py): the range checks, the boot values back after a silent
host's motion, temporary values back after host_timeout_ms of silence, and soft limits that must
leave a stroke (set by the host or saved in the params file).

Each case takes plain data (a replay data file written by the CPython test: ADC codes recorded
from the simulated actuator and calibration files made from it, testkit.model) and raises
AssertionError on failure; it returns a small dict of figures that the CPython test also checks.
"""

from testkit.replay import load, replay_app, run_steps


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
