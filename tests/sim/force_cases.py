"""Force cases on the simulated actuator (boards/sim, a physical model): the gauge hooked on a
side, force mode's steps and contact, the guided force step's open-loop points, and the load as a
bench's gauge shows it (BenchGauge). Run under both CPython and MicroPython like
tests/sim/firmware_cases.py, whose helpers they share; the offline benches call them too
(bench/bench_force_steps_offline.py).
"""

from boards.sim.machine import for_board
from tests.sim.firmware_cases import _run, load_calibration


def case_force_sim(path, targets, settle_ticks=2000, hold_ticks=500):
    """Force mode on the simulated actuator pulling the force gauge through the fibre (the paper's section 4).

    For each target: settle, then average over `hold_ticks` the firmware's force estimate
    F0(d) and the model's true spring force. Returns the worst |mean - target| of each, mN.
    """
    from firmware.app import App

    import boards.sim.machine as sim

    app = App("boards/sim.json", None, machine=for_board("boards/sim.json"))
    app.set_calibration(load_calibration(path))
    app.start()
    world = sim.world()
    world.set_load("gauge")
    sim.run_ticks(10)
    app.set_mode("force")
    out = {"est_err_mN": 0, "true_err_mN": 0}
    for target in targets:
        app.set_target(target)
        est, true = _settle_then_mean(app, world, settle_ticks, hold_ticks, spring=True)
        e = abs(est - target)
        if e > out["est_err_mN"]:
            out["est_err_mN"] = e
        e = abs(true - target)
        if e > out["true_err_mN"]:
            out["true_err_mN"] = e
    st = app.status()
    app.shutdown()
    assert st["faults"] == [] and st["mode"] == "force", st
    return out


def _settle_then_mean(app, world, settle_ticks, hold_ticks, spring=False, gauge=None):
    """Run, then average the firmware's force estimate and the true force (mN): the load's
    (the actuator's force is what the load resists), or with `spring` the spring's. With `gauge`
    (a BenchGauge) the load is left to it: it takes its readings over the hold, and None stands
    in for the load until its closing tare."""
    import boards.sim.machine as sim

    k = 0
    est = 0
    true = 0.0
    if gauge is not None:
        gauge.start_hold()
    while k < settle_ticks + hold_ticks:
        sim.run_ticks(1)
        app.heartbeat()
        if k >= settle_ticks:
            est += app.ctrl.meas.force
            true += world.spring_force_n * 1000.0 if spring else -world.external_force_n * 1000.0
            if gauge is not None and (k - settle_ticks) % GAUGE_EVERY == 0:
                gauge.read()
        k += 1
    return est // hold_ticks, (None if gauge is not None else int(true / hold_ticks))


GAUGE_EVERY = 10  # ticks between gauge readings over a hold (a display updates about 100 times a second)


class BenchGauge:
    """The load as a bench measures it, not the simulator's true force: what the gauge shows
    (boards/sim/bench_rig.gauge_reading_n: its ADC channel, with noise, 0.01 N display and zero
    drift), each reading taken against the tares before and after (fibre slack) interpolated to
    its time, with the side's sign -- as host/experiments/force_runs.py and
    host/guided/force_calibration.py do."""

    def __init__(self, world):
        self.world = world
        self.tares = []  # (t_s, N)
        self.holds = []  # per hold, its readings (t_s, N)

    def _reading(self):
        from boards.sim.bench_rig import gauge_reading_n

        return (self.world.time_s, gauge_reading_n(self.world))

    def tare(self):
        self.tares.append(self._reading())

    def start_hold(self):
        self.holds.append([])

    def read(self):
        self.holds[-1].append(self._reading())

    def loads_mN(self):
        """The mean load (mN, the actuator's sign) of each hold."""
        (t0, z0), (t1, z1) = self.tares[0], self.tares[-1]
        out = []
        for hold in self.holds:
            s = 0.0
            for t, g in hold:
                zero = z0 + (z1 - z0) * (t - t0) / (t1 - t0) if t1 > t0 else z0
                s += g - zero
            out.append(int(-self.world.gauge_side * s / len(hold) * 1000.0))
        return out


def _hooked_on_side(path, side, anchor, gap_um, board_path="boards/sim.json"):
    """A started app with the file's calibration, the block moved to `anchor` (um of D2, the
    firmware's frame) + `gap_um` on the slack side, the gauge hooked on `side` so that the fibre
    goes taut after the block has moved gap_um: (app, world, sign of the forces against it).

    The anchor is placed from where the block truly is, as boards/sim/bench_rig.py hooks it for
    the guided steps (a person sees the block, not its true millimetres). A board whose pots
    carry mounting error reads D2 up to a few mm from the simulation's true position; an anchor
    at true `anchor` would start the fibre that much slack, or stretched by tens of newtons."""
    from firmware.app import App

    import boards.sim.machine as sim

    app = App(board_path, None, machine=for_board(board_path))
    app.set_calibration(load_calibration(path))
    app.start()
    world = sim.world()
    sign = -1 if side == "high" else 1
    app.set_mode("position")
    app.set_target(anchor - sign * gap_um)
    _run(app, 1500)
    gap_mm = gap_um / 1000.0
    world.set_load("gauge", anchor_mm=world.block_mm - gap_mm if side == "high" else world.block_mm + gap_mm, side=side)
    return app, world, sign


def case_force_points_sim(path, side, levels, anchor=45000, board_path="boards/sim.json", stop_mN=0, stop_um=0,
                          measured=False):
    """Force identification as the guided step does it, on the simulated actuator: open-loop duty
    steps loading then unloading against a gauge on `side`; rows [d um, load force mN, loading].
    With `stop_mN` (and `stop_um`) the loading ends at the first level whose load (deformation)
    reaches it, as the guided step's --force-range (and CAVITY_NEAR_MM) end it, and the
    unloading goes down from there. The load is the simulator's true one, or with `measured` what
    the gauge shows (BenchGauge, tared with the fibre slack before and after; the stop then
    judges the true load, a shortcut a bench takes by eye)."""
    gap = 1500
    app, world, sign = _hooked_on_side(path, side, anchor, gap, board_path)
    gauge = BenchGauge(world) if measured else None
    if gauge is not None:
        gauge.tare()
    app.set_mode("open_loop")
    rows = []
    previous = 0
    top = len(levels)
    n = 0
    while n < 2 * top - 1:
        loading = 1 if n < top else 0
        duty = levels[n] if loading else levels[2 * top - 2 - n]
        j = 1
        while j <= 10:  # ramped over 0.3 s, as host/guided/force_calibration.py does
            app.set_target(sign * (previous + (duty - previous) * j // 10))
            _run(app, 30)
            j += 1
        previous = duty
        _run(app, 500)  # come to rest against the fibre
        k = 0
        defl = 0
        if gauge is not None:
            gauge.start_hold()
        while k < 300:
            _run(app, 1)
            defl += app.ctrl.meas.defl
            if gauge is not None and k % GAUGE_EVERY == 0:
                gauge.read()
            k += 1
        rows.append([defl // 300, int(-world.external_force_n * 1000.0), loading])
        if loading and n < top - 1 and ((stop_mN and abs(rows[-1][1]) >= stop_mN) or (stop_um and abs(rows[-1][0]) >= stop_um)):
            top = n + 1  # unload from this level
            n = top - 1
        n += 1
    if gauge is not None:
        _back_to_slack(app, anchor - sign * gap)
        gauge.tare()
        for row, load_mN in zip(rows, gauge.loads_mN()):
            row[1] = load_mN
    app.shutdown()
    return rows


def case_force_steps_sim(path, side, targets, anchor=45000, settle_ticks=1500, hold_ticks=500, preload=500,
                         board_path="boards/sim.json", measured=False):
    """Force steps against a gauge on `side`, the fibre just slack, then taken up by a `preload` mN
    hold (as host/experiments/force_runs.py does): [target, estimate, load] mN each. The load is
    the simulator's true one, or with `measured` what the gauge shows (BenchGauge: tared with the
    fibre slack before the steps and after them)."""
    gap = 200
    app, world, sign = _hooked_on_side(path, side, anchor, gap, board_path)
    gauge = BenchGauge(world) if measured else None
    if gauge is not None:
        gauge.tare()
    app.set_mode("force")
    if preload:
        app.set_target(sign * preload)
        _run(app, 500)
    rows = []
    for t in targets:
        app.set_target(t)
        est, load_mN = _settle_then_mean(app, world, settle_ticks, hold_ticks, gauge=gauge)
        rows.append([t, est, load_mN])
    st = app.status()
    if gauge is not None:
        _back_to_slack(app, anchor - sign * gap)
        gauge.tare()
        for row, load_mN in zip(rows, gauge.loads_mN()):
            row[2] = load_mN
    app.shutdown()
    assert st["faults"] == [] and st["mode"] == "force", st
    return rows


def _back_to_slack(app, target_um):
    """Position mode back to where the fibre hung slack (the closing tare's place)."""
    app.set_mode("position")
    app.set_target(target_um)
    _run(app, 1500)


def case_force_contact_sim(path, side, target, gap_um, board_path="boards/sim.json", ticks=2000):
    """Force mode switched on with the fibre `gap_um` slack: the block slides free until the
    fibre takes it. Returns the largest lead of the deformation setpoint over the measured
    deformation in the target's direction (um) and the largest true spring force in it (mN)."""
    import boards.sim.machine as sim

    app, world, sign = _hooked_on_side(path, side, 45000, gap_um, board_path)
    app.set_mode("force")
    app.set_target(sign * target)
    lead = 0
    peak = 0.0
    k = 0
    while k < ticks:
        sim.run_ticks(1)
        app.heartbeat()
        c = app.ctrl
        v = sign * (c.defl_sp - c.meas.defl)
        if v > lead:
            lead = v
        f = sign * world.spring_force_n * 1000.0
        if f > peak:
            peak = f
        k += 1
    app.shutdown()
    return {"lead_um": lead, "spring_peak_mN": int(peak)}


def case_force_approach_sim(path, side, target, ticks=1500):
    """A force step from a 0.5 N preload: how the deformation setpoint closes on its goal (the
    band edge it ramps to). Returns the steps it spent with its goal 3-127 um ahead and 3-16 um
    ahead (moving or not), the largest move it made with its goal 1-16 um ahead (um; the last
    um too, where a jump to the goal would show), and whether it sits on its goal at the end (it
    closes on it, it does not stall short of it)."""
    import boards.sim.machine as sim

    app, world, sign = _hooked_on_side(path, side, 45000, 200)
    app.set_mode("force")
    app.set_target(sign * 500)
    _run(app, 500)
    app.set_target(sign * target)
    c = app.ctrl
    near = 0
    end = 0
    largest = 0
    prev = c.defl_sp
    k = 0
    while k < ticks:
        sim.run_ticks(1)
        app.heartbeat()
        sp = c.defl_sp
        goal = c.force_set[c.fdir + 1]
        ahead = (goal - prev) if goal > prev else (prev - goal)
        moved = (sp - prev) if sp > prev else (prev - sp)
        if 2 < ahead < 128:
            near += 1
        if 2 < ahead <= 16:
            end += 1
        if 0 < ahead <= 16 and moved > largest:
            largest = moved
        prev = sp
        k += 1
    at_goal = c.defl_sp == c.force_set[c.fdir + 1]
    app.shutdown()
    return {"near_steps": near, "end_steps": end, "largest_end_um": largest, "at_goal": at_goal}
