"""Firmware cases on the simulated actuator (boards/sim, a physical model), run under both CPython
and MicroPython like tests/firmware/app_cases.py. `path` is a calibration file (testkit.model),
loaded by the firmware's own loader.
"""

from boards.sim.machine import for_board


def load_calibration(path):
    """The firmware's Calibration of the file at `path` (imported here, not at the top: a test
    may have replaced the firmware modules by then)."""
    from firmware.calibration import load_calibration as load_file

    return load_file(path)


def case_position_sim(path, targets, settle_ticks=1500, hold_ticks=300):
    """Position mode on the simulated actuator (boards/sim, a physical model) from mid-stroke.

    For each target: settle, then over `hold_ticks` record the firmware's own D2 and the true
    travel of pot 2's wiper (the quantity pot 2 was calibrated against, so the two agree up to
    the calibration and noise errors). Returns the worst of each, and the worst overshoot.
    """
    from firmware.app import App

    import boards.sim.machine as sim

    app = App("boards/sim.json", None, machine=for_board("boards/sim.json"))
    app.set_calibration(load_calibration(path))
    app.start()
    world = sim.world()
    pot2 = world.pots[1]
    sim.run_ticks(10)
    app.set_mode("position")
    out = {"fw_err_um": 0, "true_err_um": 0, "overshoot_um": 0}
    for target in targets:
        app.set_target(target)
        start = app.ctrl.meas.d2
        k = 0
        while k < settle_ticks + hold_ticks:
            sim.run_ticks(1)
            app.heartbeat()
            x = world.block_mm
            travel = int((x + pot2.mount_error_mm(x)) * 1000.0)
            over = travel - target if target > start else target - travel
            if over > out["overshoot_um"]:
                out["overshoot_um"] = over
            if k >= settle_ticks:
                e = abs(app.ctrl.meas.d2 - target)
                if e > out["fw_err_um"]:
                    out["fw_err_um"] = e
                e = abs(travel - target)
                if e > out["true_err_um"]:
                    out["true_err_um"] = e
            k += 1
    st = app.status()
    app.shutdown()
    assert st["faults"] == [] and st["mode"] == "position", st
    return out


def case_boot_calibration_file(good_path, bad_path):
    """App reads the calibration file at boot: a good file enables closed loop (status has its
    CRC); a corrupt one leaves raw readings and open loop working and says why closed loop is
    refused."""
    from firmware.app import App

    good = App("boards/sim.json", good_path, machine=for_board("boards/sim.json"))
    st = good.status()
    assert st["calibration_error"] is None and isinstance(st["calibration_crc"], int), st
    good.step(None)
    good.set_mode("position")
    good.set_mode("force")
    bad = App("boards/sim.json", bad_path, machine=for_board("boards/sim.json"))
    st = bad.status()
    assert st["calibration_crc"] is None and "CRC" in st["calibration_error"].upper(), st
    try:
        bad.set_mode("position")
        raise AssertionError("closed loop accepted with a corrupt calibration")
    except ValueError as exc:
        assert "calibration" in str(exc)
    bad.set_mode("open_loop")
    bad.set_target(1000)
    bad.step(None)
    assert bad.ctrl.duty > 0 and bad.sampler.raw2 > 0
    missing = App("boards/sim.json", bad_path + ".absent", machine=for_board("boards/sim.json"))
    assert "no calibration file" in missing.status()["calibration_error"], missing.status()
    return {"crc": good.status()["calibration_crc"], "error": st["calibration_error"]}


def _run(app, ticks):
    """Advance the simulated board `ticks` control periods, the host heard at each."""
    import boards.sim.machine as sim

    k = 0
    while k < ticks:
        sim.run_ticks(1)
        app.heartbeat()
        k += 1


def case_wiper_lift_sim(path, pot):
    """A wiper lift in the physical model (boards/sim inject_fault) while position mode drives
    the motor: the very next timer tick leaves 0 V across the motor and names the pot."""
    from firmware.app import App

    import boards.sim.machine as sim

    app = App("boards/sim.json", None, machine=for_board("boards/sim.json"))
    app.set_calibration(load_calibration(path))
    app.start()
    sim.run_ticks(10)
    app.set_mode("position")
    app.set_target(app.ctrl.meas.d2 + 10000)
    sim.run_ticks(50)
    assert sim.motor_voltage() > 0.5, sim.motor_voltage()
    sim.world().inject_fault(pot, "wiper_lift")
    sim.run_ticks(1)
    volts = sim.motor_voltage()
    st = app.status()
    app.shutdown()
    assert volts == 0, volts
    assert st["faults"] == ["rail_" + pot] and pot in st["last_fault"], st
    return {"fault": st["last_fault"]}


def case_stroke_limits_sim(path, duty=10000, ticks=1500):
    """Soft stroke limits on the simulated actuator: open loop at `duty` toward each end stops
    the motor with the nut and the block short of the firmware's limit and off the hard end stop,
    and only slows near it; a position target inside the slow zone still settles.
    Returns the extremes reached (um, true positions) and the duty seen on the way."""
    from firmware.app import App

    import boards.sim.machine as sim

    app = App("boards/sim.json", None, machine=for_board("boards/sim.json"))
    app.set_calibration(load_calibration(path))
    app.start()
    world = sim.world()
    lo, hi = app.ctrl.stroke_limits
    zone = app.get_param("slow_zone_um")
    sim.run_ticks(10)
    out = {}
    for sign in (1, -1):
        app.set_mode("open_loop")
        app.set_target(sign * duty)
        extreme = -1000.0
        far_duty = 0  # the largest duty while more than a slow zone from the limit
        k = 0
        while k < ticks:
            sim.run_ticks(1)
            app.heartbeat()
            m = app.ctrl.meas
            pos = world.block_mm if sign > 0 else -world.block_mm
            nut = world.nut_mm if sign > 0 else -world.nut_mm
            if max(pos, nut) > extreme:
                extreme = max(pos, nut)
            room = hi - m.d2 if sign > 0 else m.d2 - lo
            if room > zone and abs(app.ctrl.duty) > far_duty:
                far_duty = abs(app.ctrl.duty)
            if room < zone // 4:
                assert abs(app.ctrl.duty) <= 10000 * max(room, 0) // zone + 1, (room, app.ctrl.duty)
            k += 1
        assert app.ctrl.duty == 0 or abs(app.ctrl.duty) <= 10000 * 100 // zone, app.ctrl.duty
        assert far_duty == duty, far_duty  # full speed away from the ends: a cap, not a fade
        out["top_um" if sign > 0 else "bottom_um"] = int(extreme * 1000.0) * sign
    assert world.block_mm > 0.05 and world.nut_mm > 0.05, (world.block_mm, world.nut_mm)
    app.set_mode("position")
    target = hi - zone // 6
    app.set_target(target)
    k = 0
    while k < 3000:
        sim.run_ticks(1)
        app.heartbeat()
        k += 1
    out["held_um"] = int(world.pots[1].wiper_mm(world.block_mm) * 1000.0)
    out["target_um"] = target
    st = app.status()
    app.shutdown()
    assert st["faults"] == [], st
    return out


class QuittingLink:
    """Polled by run(): keeps the host alive, drives open loop, asks run() to return after
    `ms` of wall-clock time (the simulated board advances in real time in machine.idle())."""

    def __init__(self, app, ms):
        import time

        self.time = time
        self.app = app
        self.ms = ms
        self.t0 = None
        self.volts_seen = 0.0

    def poll(self):
        import boards.sim.machine as sim

        t = self.time
        now = t.ticks_ms() if hasattr(t, "ticks_ms") else int(t.monotonic() * 1000)
        if self.t0 is None:
            self.t0 = now
            self.app.set_mode("open_loop")
            self.app.set_target(3000)
        self.app.heartbeat()
        v = sim.motor_voltage()
        if v > self.volts_seen:
            self.volts_seen = v
        if now - self.t0 >= self.ms:
            self.app.quit()


def case_run_realtime_sim():
    """run() on the simulated board: the timer fires from machine.idle() in real time, the link
    is polled, and a normal return from run() also leaves the motor off."""
    from firmware.app import App

    import boards.sim.machine as sim

    app = App("boards/sim.json", None, machine=for_board("boards/sim.json"))
    link = QuittingLink(app, 300)
    app.run(link)
    st = app.status()
    assert link.volts_seen > 0.5, link.volts_seen
    assert sim.motor_voltage() == 0 and st["mode"] == "idle", st
    assert app.ctrl.steps >= 100, app.ctrl.steps  # 300 ms at 1 kHz, allowing for a slow host
    return {"ok": True}


def case_position_sticky_sim(path, board_path, targets, settle_ticks=2500, hold_ticks=1000):
    """Position mode on a sticky actuator (the board file's block friction): for each target,
    after `settle_ticks`, the block's true position (pot 2's wiper travel, what pot 2 was
    calibrated against) over `hold_ticks`: its error and how far it moved (a limit cycle moves
    it), and the first tick from which it stayed within 50 um of the target (settle time)."""
    from firmware.app import App

    import boards.sim.machine as sim

    app = App(board_path, None, machine=for_board(board_path))
    app.set_calibration(load_calibration(path))
    app.start()
    world = sim.world()
    pot2 = world.pots[1]
    sim.run_ticks(10)
    app.set_mode("position")
    out = {"true_err_um": 0, "moved_um": 0, "settle_ticks": 0}
    for target in targets:
        app.set_target(target)
        lo = hi = None
        inside_since = None
        k = 0
        while k < settle_ticks + hold_ticks:
            sim.run_ticks(1)
            app.heartbeat()
            x = world.block_mm
            travel = int((x + pot2.mount_error_mm(x)) * 1000.0)
            if abs(travel - target) <= 50:
                inside_since = k if inside_since is None else inside_since
            else:
                inside_since = None
            if k >= settle_ticks:
                lo = travel if lo is None or travel < lo else lo
                hi = travel if hi is None or travel > hi else hi
                e = abs(travel - target)
                if e > out["true_err_um"]:
                    out["true_err_um"] = e
            k += 1
        if hi - lo > out["moved_um"]:
            out["moved_um"] = hi - lo
        settled = settle_ticks + hold_ticks if inside_since is None else inside_since
        if settled > out["settle_ticks"]:
            out["settle_ticks"] = settled
    st = app.status()
    app.shutdown()
    assert st["faults"] == [] and st["mode"] == "position", st
    return out


