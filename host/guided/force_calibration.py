"""Calibration 3 (the paper's section 4): force from spring deformation, F0(d), its inverse, and the
output block's friction.

The block pulls a force gauge through a fibre. Each round loads and unloads in open-loop duty
steps (the motor stalls against the fibre, so the duty sets the force without knowing the fibre's
stiffness); at each step, once still, the firmware's deformation d = D1* - D2 (Df-corrected, so
the assembly step must be done) and the gauge reading are averaged. The gauge is tared with the
fibre slack first. The paper pulls the block toward 0 mm only (gauge on the 60 mm side, negative
actuator forces); by default the gauge is then moved to the 0 mm side and the rounds repeated, so
that F0(d) is measured for both signs of force.

The fit (F0, its inverse and the friction term, orders by cross-validation) is
host/fitting/force.py.
"""

import time

import numpy as np

from host.calibration.file import force_range_section
from host.errors import UserError
from host.fitting.force import fit_force, hysteresis_n
from host.guided.force_identification import (SIDES, TAUT_N, check_gauge_follows, force_sections, identify,
                                              plot_force, poly_text, usable_range)
from host.guided import acquire
from host.guided.outcome import StepOutcome
from host.guided.prompts import end_progress, progress_line

STEP_SPAN_DUTY = 5000  # --levels N: loading steps of 5000 / N duty (about 17 N in N steps on boards/sim.json)
CAVITY_NEAR_MM = 1.8  # |d| beyond this: the nut is near the cavity wall, F0(d) turns vertical


def gauge_sides(choice):
    """The gauge sides a --gauge-sides choice runs, in order."""
    return ("high", "low") if choice == "both" else (choice,)


def held_range(usable):
    """(the force_range section, its line) from {gauge side: the force magnitude it held below any
    hard contact, N}: the board refuses force targets beyond it. A side the gauge was not hooked on
    takes the other's magnitude, and the line says it was not measured (the spring pair and the
    motor are alike both ways, but nobody saw it)."""
    # a side that held no more than a taut fibre's force (or nothing) was not measured
    measured = {SIDES[side]: float(n) for side, n in usable.items() if n and n > 2 * TAUT_N}
    if not measured:
        return None, "force: no side held a force: the board keeps the protocol's +-200 N as its range"
    reach = {sign: measured.get(sign, max(measured.values())) for sign in (-1, 1)}
    assumed = [sign for sign in (-1, 1) if sign not in measured]
    section = force_range_section(-reach[-1], reach[1], {"measured": [sign for sign in (-1, 1) if sign in measured],
                                                          "assumed": assumed})
    return section, "force: targets %+.2f .. %+.2f N are taken (what the force step held%s); beyond them force mode " \
        "refuses" % (-reach[-1], reach[1], "; the %s side was not measured and takes the other's" % (
            "negative" if assumed == [-1] else "positive") if assumed else "")


def slack_position_mm(anchor_mm, side, gap_mm=1.5):
    """Where the block waits while the fibre hangs slack: `gap_mm` on the slack side of the anchor."""
    return anchor_mm + gap_mm if side == "high" else anchor_mm - gap_mm


def _move_slack(client, start):
    ok, _, _ = acquire.hold(client, "position", int(start * 1000), "d2_um", 300, timeout_s=10)
    client.call("stop")
    if not ok:
        status = client.call("status")
        raise UserError("could not move the block to %.1f mm, where the fibre hangs slack (mode %s, faults %s)" % (
            start, status.get("mode"), ", ".join(status.get("faults") or []) or "none"))


class GaugeOnSide:
    """The force gauge hooked on one side, read against its drifting zero.

    The gauge's zero drifts (the paper notes it; 0.3 N/min would be 0.1 N over a side's rounds,
    2 % of 5 N), so the caller slackens the fibre and tares (`tare()`) before and after its
    loading; `forces()` takes every reading against the tare interpolated to its time, and
    gives it the side's sign (the gauge shows tension; pulling the block toward 0 mm is a
    negative actuator force)."""

    def __init__(self, session, rig, prompter, anchor_mm, side, gap_mm=1.5):
        self.client = session.client
        self.rig = rig
        self.side = side
        self.start = slack_position_mm(anchor_mm, side, gap_mm)
        if (rig.state["load"] or {}).get("kind") == "gauge":  # the other side's gauge would hold the block
            rig.no_load()
        prompter.say("  moving the block to %.1f mm, where the fibre will hang slack" % self.start)
        _move_slack(self.client, self.start)
        rig.hook_gauge(anchor_mm, side, gap_mm=gap_mm)
        self.tare_t, self.tares, self.read_t, self.readings = [], [], [], []

    def read(self, records=None, reads=1):
        """One reading in N (display readings averaged, or the gauge channel over `records`)."""
        if self.rig.gauge == "adc":
            return self.rig.read_gauge_n(self.client, records)
        return float(np.mean([self.rig.gauge_reading_n(beat=self.client.heartbeat_if_due) for _ in range(reads)]))

    def tare(self, move=False):
        """Tare with the fibre slack (after moving the block back to slack when `move`)."""
        if move:
            self.client.call("stop")
            _move_slack(self.client, self.start)
        self.tares.append(self.read(reads=3 if self.rig.virtual else 1))  # a person reads each tare once
        self.tare_t.append(time.monotonic())

    def record(self, records=None):
        """Take a loaded reading now (kept with its time); returns its raw value."""
        g = self.read(records)
        self.readings.append(g)
        self.read_t.append(time.monotonic())
        return g

    def forces(self):
        """The actuator forces (N) of every recorded reading, against the interpolated tare."""
        zero = np.interp(self.read_t, self.tare_t, self.tares)
        return SIDES[self.side] * (np.array(self.readings) - zero)


RAMP_STEPS = 10
RAMP_S = 0.3


def _ramp_duty(client, start, end):
    """Open-loop duty from `start` to `end` in RAMP_STEPS steps over RAMP_S. A jump makes the heavy
    nut ring against the spring and the fibre, and the block then sticks anywhere inside its
    friction band; ramped, it comes to rest with the full Coulomb friction against it, as it does
    under force mode's ramped setpoint (firmware defl_rate_um; docs/guided-calibration.md has
    what jumps cost)."""
    for j in range(1, RAMP_STEPS + 1):
        client.call("target", int(round(start + (end - start) * j / RAMP_STEPS)))
        time.sleep(RAMP_S / RAMP_STEPS)


def force_points(session, rig, prompter, opts, side="high"):
    """(d_mm, force_N, s, loading, tares, duty) from `opts.rounds` loading/unloading rounds against a
    gauge on `side`, tared before the first round and after every round (GaugeOnSide).
    force_N is the actuator's force (negative toward 0 mm); s is the friction direction of
    each point (+1 after the force fell, -1 after it rose)."""
    client = session.client
    sign = SIDES[side]
    gauge = GaugeOnSide(session, rig, prompter, opts.anchor_mm, side)
    prompter.say("  taring the gauge (fibre slack)")
    gauge.tare()
    # The duty a force needs depends on the motor, the supply and the screw, so the first
    # round's loading goes up in equal steps until the gauge reads opts.force_range (or the duty
    # reaches opts.max_duty, or the spring nears the cavity wall); every round then uses those
    # levels. The fit is only trusted over the forces it saw: a weak motor's 5000 duty reached
    # 7.5 N, and a linear F0 carried out to 15 N missed by 20 %.
    step = _ladder_step(client, gauge, sign, STEP_SPAN_DUTY / opts.levels, opts, prompter)
    levels = []
    d, loading, duties = [], [], []
    for r in range(opts.rounds):
        client.call("mode", "open_loop")
        previous = 0.0
        for load in (True, False):
            seq = levels[::-1][1:] if not load else (levels or _levels_until(step, opts.max_duty))
            for duty in seq:
                _ramp_duty(client, sign * previous, sign * duty)
                previous = duty
                acquire.collect(client, opts.settle_s)  # let it come to rest against the fibre
                rec = deformation_records(client)
                d.append(acquire.mean(rec, "defl_um") / 1000.0)
                g = gauge.record(rec)
                loading.append(load)
                duties.append(sign * duty)
                progress_line("  %s side, round %d/%d %s duty %+5d: d %+.3f mm, gauge %.2f N" % (
                    side, r + 1, opts.rounds, "loading  " if load else "unloading", sign * duty, d[-1], g))
                if load and r == 0:
                    levels.append(duty)
                    if abs(g - gauge.tares[-1]) >= opts.force_range or abs(d[-1]) >= CAVITY_NEAR_MM:
                        break
        gauge.tare(move=True)
    end_progress()
    client.call("stop")
    loading = np.array(loading)
    # Loading against the high-side gauge makes the force fall (more negative): the block slides
    # toward 0 mm, s = +1; on the low side loading makes it rise, s = -1.
    s = np.where(loading, 1.0, -1.0) * -SIDES[side]
    forces = gauge.forces()
    check_gauge_follows(np.array(d), forces, side)
    return np.array(d), forces, s, loading, gauge.tares, np.array(duties, dtype=float)


MIN_STEP_DUTY = 100
STRONG = 1.5  # a first step this many times force_range / levels newtons: the motor is strong, the steps shrink


def _ladder_step(client, gauge, sign, step, opts, prompter):
    """The loading ladder's duty step: `step`, or less when one such step makes more than STRONG
    times force_range / levels newtons. A fine screw, a high gear ratio or a high supply makes a
    strong motor: on one fresh actuator (0.41 mm lead, gear 1.26, 8.3 V) 625 duty made 4 N, the
    ladder reached 16 N in four levels, the last through the spring's hard contact, and F0 was
    fitted to five points a side. One step is tried (ramped up, read, ramped back down) before
    the rounds; the steps then aim at force_range / levels newtons each."""
    want = opts.force_range / opts.levels
    client.call("mode", "open_loop")
    _ramp_duty(client, 0, sign * step)
    acquire.collect(client, opts.settle_s)
    made = abs(gauge.read(acquire.collect(client, 0.3)) - gauge.tares[-1])
    _ramp_duty(client, sign * step, 0)
    client.call("stop")
    if made <= STRONG * want:
        return step
    smaller = max(MIN_STEP_DUTY, step * want / made)
    prompter.say("  a first step of %d duty made %.1f N: the ladder goes up in steps of %d duty" % (step, made, smaller))
    return smaller


def _levels_until(step, cap):
    """Loading duties step, 2 step, ... up to cap: the first round stops early at the force range."""
    n = max(1, int(cap // step))
    return [step * (i + 1) for i in range(n)]


DEFL_SE_UM = 1.5  # the standard error a point's mean deformation is averaged down to
POINT_S = (0.3, 1.5)  # ... over at least and at most this long (board seconds)


def deformation_records(client):
    """Telemetry at rest for one force point: 0.3 s, and more until the mean deformation's
    standard error is DEFL_SE_UM (1.5 s at most). Noisy pots on a stiff spring otherwise put
    their noise into F0: 5 LSB of pot noise left 5 um on a 0.3 s mean, 0.1 N at 19 N/mm."""
    rec = acquire.collect(client, POINT_S[0])
    while len(rec) > 2 and len(rec) < POINT_S[1] * acquire.STREAM_HZ:
        d = rec[:, acquire.COL["defl_um"]].astype(float)
        if np.std(d) / np.sqrt(len(d)) <= DEFL_SE_UM:
            break
        rec = np.concatenate([rec, acquire.collect(client, POINT_S[0])])
    return rec


def calibrate_force(session, rig, prompter, opts, calibration_path):
    from host.calibration.file import read_calibration

    doc = read_calibration(calibration_path) if calibration_path.exists() else {}
    if not doc.get("df"):
        raise UserError("the force step needs the assembly (Df) calibration first: host calibrate assembly")
    sides = gauge_sides(opts.gauge_sides)
    low, high = rig.ends
    prompter.say("[force] %d loading/unloading rounds against the force gauge, gauge on the %s side%s" % (
        opts.rounds, " then the ".join(high if x == "high" else low for x in sides), "s" if len(sides) > 1 else ""))
    parts = [force_points(session, rig, prompter, opts, side) for side in sides]
    rig.no_load()
    d, f, s, loading = (np.concatenate([p[i] for p in parts]) for i in range(4))
    tares = [t for p in parts for t in p[4]]
    duty = np.concatenate([p[5] for p in parts])
    taut = np.abs(f) > TAUT_N
    if np.count_nonzero(taut) < 6:
        return StepOutcome("force", {}, ["force: the gauge never read a force (is the fibre hooked?)"], [], ok=False)
    dt, ft, st, lt = d[taut], f[taut], s[taut], loading[taut]
    fit, drive, unexported = identify(dt, ft, st, lt, duty[taut], opts.force_order, opts.friction)
    plain = fit_force(dt, ft, st, fit.order_f, friction=False, tables=False)  # what the paper's fit leaves
    hyst = max(hysteresis_n(dt[ft < 0], ft[ft < 0], lt[ft < 0], fit.order_f) if np.any(ft < 0) else 0.0,
               hysteresis_n(dt[ft > 0], ft[ft > 0], lt[ft > 0], fit.order_f) if np.any(ft > 0) else 0.0)
    lines = [
        "force: %d points (%d taut), gauge %s, tares %s N (interpolated in time: the zero drifts), d %.3f..%.3f mm, "
        "F0 %.2f..%.2f N" % (len(d), len(dt), " and ".join(sides), ", ".join("%.2f" % t for t in tares), dt.min(), dt.max(),
                             ft.min(), ft.max()),
        "force: F0(d) = %s  (N, mm)" % poly_text(fit.coeffs_f, "d") if fit.kind == "poly" else
        "force: F0(d) is a cubic spline with a kink where a spring lifts off its preload (kinks at d = %s mm; cross-validated "
        "rms %.3f N against %.3f N for the best polynomial), tabulated in %d knots" % (
            ", ".join("%.2f" % r for r in fit.kinks_mm) or "none", min(fit.spline_scores.values()),
            min(fit.scores.values()), len(fit.knots_d)) if fit.kinks_mm is not None else
        "force: F0(d) is a %d-knot table (cross-validated rms %.3f N against %.3f N for the best polynomial): "
        "d %s mm -> F0 %s N" % (len(fit.knots_d), min(fit.table_scores.values()), min(fit.scores.values()),
                              ", ".join("%.3f" % v for v in fit.knots_d), ", ".join("%.2f" % v for v in fit.knots_f)),
        "force: block friction h = %.3f N; fit rms %.3f N, max %.3f N (without the friction term: rms %.3f N)%s" % (
            fit.friction_n, fit.rms_n, fit.max_n, plain.rms_n,
            "; %d point(s) left out just after a turn or at a round's start: the spring had moved less than 2h "
            "since, so the block had not slid to the band's edge" % np.count_nonzero(fit.left_out)
            if np.any(fit.left_out) else "") if opts.friction else
        "force: no friction term (--no-friction); fit rms %.3f N, max %.3f N" % (fit.rms_n, fit.max_n),
        "force: d(F0) = %s  (mm, N of spring force; rms %.1f um)" % (
            poly_text(fit.coeffs_d, "F") if fit.kind == "poly" else "the table's inverse", 1000 * fit.rms_d_mm),
        "force: loading/unloading hysteresis %.3f N (largest gap between the two fits)" % hyst,
        "force: cross-validated rms by order: " + ", ".join("%d: %.3f N" % kv for kv in fit.scores.items()),
        "force: the motor holds %.2f N per 1000 duty at stall (%+.2f N at zero duty): %d duty holds the spring at the "
        "friction force (position control adds it to break the block free)" % (
            1000 * drive.n_per_duty, drive.offset_n, drive.ff_duty) if drive.ff_duty else
        "force: no friction feed-forward for position control (%s)" % drive.why,
    ] + ([unexported] if unexported else [])
    usable = {}
    for side in sides:
        reached, below, contact = usable_range(d, f, loading, duty, side, fit.friction_n)
        usable[side] = below
        if contact is not None:
            lines.append("force: on the %s side the spring went into hard contact (the nut at the cavity's wall) between "
                         "%.1f and %.1f N: the trim and the experiments stay below %.1f N there" % (side, below, contact, below))
    stats_f = {"order": fit.order_f, "rms_n": fit.rms_n, "max_n": fit.max_n, "hysteresis_n": hyst,
               "left_out": int(np.count_nonzero(fit.left_out)),
               "tare_n": tares, "sides": list(sides), "rms_without_friction_n": plain.rms_n,
               "usable_n": usable}
    sections = force_sections(fit, drive, stats_f)
    sections["force_range"], line = held_range(usable)
    lines.append(line)
    png = opts.plot_path("force")
    inside = np.zeros(len(d), dtype=bool)
    inside[np.flatnonzero(taut)[fit.left_out]] = True
    plot_force(png, d, f, s, fit, inside)
    data = {"d_mm": d, "force_n": f, "s": s, "loading": loading, "duty": duty, "order": fit.order_f,
            "coeffs_f": fit.coeffs_f, "coeffs_d": fit.coeffs_d, "kind": fit.kind,
            "knots_d": fit.knots_d, "knots_f": fit.knots_f, "kinks_mm": fit.kinks_mm,
            "friction_n": fit.friction_n, "hysteresis_n": hyst, "rms_n": fit.rms_n, "rms_plain_n": plain.rms_n,
            "sides": sides, "usable_n": usable}
    return StepOutcome("force", sections, lines, [png], ok=True, data=data)


