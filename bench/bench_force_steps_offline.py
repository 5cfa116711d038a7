"""Offline force steps against the gauge on simulated actuators (lsea-kit issue 11).

What it runs: tests/sim/force_cases.py case_force_steps_sim -- the real firmware App on the
simulated actuator, advanced with run_ticks on CPython (no real time, deterministic) -- with the
bench's steps: 5, 10, 15, 10, 5 N on each side of the gauge ("high" and "low"), after a 0.5 N
preload, each step settled 1.5 s (1500 ticks) then measured 0.5 s (500 ticks).

Which actuators: for each SEED, the board file RUNS/board-SEED.json and the calibration the
robustness run identified for it, RUNS/run-SEED/calibration.json; with seed "sim", the
repository's boards/sim.json and RUNS/run-base/calibration.json (skipped if that file is missing).
With --refit the run's force sections are identified again by replaying the guided force step
(refit_calibration: the run's pots and Df, the fit of today's code), so that a change to the
force fit can be judged on the same actuators without a robustness run.
With --trim the calibration's friction is first trimmed in closed loop, as the guided calibration
does after the force step (trimmed_calibration, host/guided/friction_trim.py).
With --exact the identified calibration is replaced by an exact model calibration of that board
(testkit/model.py write_model_calibration): F0 tabled against the deformation the firmware
measures (the pots' mount errors and the Df travel included, the block where the gauge holds it
for that force) and the friction section equal to the board's true coulomb_n.

Call (from the repository root, the venv's python):
    python bench/bench_force_steps_offline.py [--runs DIR] [--exact | --refit] [--trim] [--anchors UM,UM] [SEED ...]
    python bench/bench_force_steps_offline.py [--runs DIR] [--exact] --trace SEED SIDE
    python bench/bench_force_steps_offline.py [--runs DIR] --ident [--anchors UM,UM] [SEED ...]
--anchor UM moves the gauge anchor (default 45000 um of D2, where the guided force step and the
paper's force runs hook it; the fibre is hooked from where the block is, as the virtual rig does):
the same board at another block position, another realisation of the noise and the friction's
stick states, to see how much a result moves;
--anchors UM,UM,... runs each seed at several and prints a tally over all (seed, anchor) cases,
and per seed the mean, spread and range of its worst step over the anchors.
Diagnostics (each changes what is run, and says so in the tally line):
    --param NAME=VALUE   a firmware parameter's default replaced (protocol.PARAMS), e.g. kp_force=1280
    --oversample N       every board read N times a step (the run's own value is used otherwise)
    --oversample-times K the run's own reads a step times K, at most 64 (with --loop-hz 250 and
                         K 4: as many reads a second as the run's at 1 kHz)
    --noise LSB          both pots' noise set to LSB (what the loop does with quieter pots)
    --friction true|identified   the calibration's friction h replaced by the board's true one or
                         the force step's identified one (what the trim changes)
    --filter-shift N     the estimate's average over 2**N steps instead of measurement.filter_shift's
    --loop-hz HZ         every board's loop rate (CircuitPython's 250 Hz); settle and hold keep
                         their seconds
SEEDs default to 1000 1001 1005 1006 1007 sim; DIR defaults to out/robF (what
`bench/bench_robustness.py --draws 8 --out out/robF` writes).

Loads are what the gauge shows (tests/sim/force_cases.py BenchGauge: its channel's noise, the
display's 0.01 N, its zero drift, tared with the fibre slack before and after each side's steps),
as a bench measures them, for the scores, the trim's holds and the refit's points; --true-load
uses the simulator's true load instead (a diagnostic no bench has; the tally line says which).
--ident and --trace compare against the true load (they look inside the physics).

What it prints: per seed one line: the worst steady-state error |load - target| / target and the
worst estimation error |estimate - load| / load (%, over both sides), at the 5 N steps and over all
steps (the target is 2 %). With --trace, per step of that seed and side: the extreme the true
spring force reached during the step in the step's direction, the extreme of the firmware's
64-step-filtered F0(d) in that direction, their gap (spring - F0), estimate - load (mN,
the hold's means) and the true spring force's standard deviation during the hold (mN: how much
the loop moves the spring while it holds), with the block friction h of the board: the part-1 finding is that the force
loop ratchets the block to the true spring force's extreme while the filtered F0 flattens it, so
gap ~ estimate - load.
"""

import argparse
import json
import os
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

TARGETS = (5000, 10000, 15000, 10000, 5000)
PRELOAD = 500


class Run:
    """What this invocation runs, set once from the options (main) and read by every case; the
    defaults are the bench's plain run. bench/bench_force_error_budget.py sets it as well."""

    settle = 1500  # ticks each step settles, then is measured over `hold` (1.5 s and 0.5 s at 1 kHz)
    hold = 500
    anchor_um = 45000  # the gauge anchor in force now (--anchor, --anchors: other realisations of a board)
    at_gauge = False  # --at-gauge: anchors are offsets from each board's own gauge anchor, where --trim holds too
    measured = True  # the loads the gauge shows (BenchGauge), or with --true-load the simulator's true ones
    refit = False  # --refit
    trim = False  # --trim, --no-f0, --trim-fractions
    trim_f0 = True
    trim_fractions = None
    # diagnostics: --oversample, --oversample-times, --noise, --loop-hz, --friction
    oversample = None
    oversample_times = None
    noise = None
    loop_hz = None
    friction = None

    def at_rate(self, loop_hz):
        """Every board at `loop_hz`; settle and hold keep their seconds."""
        self.loop_hz = loop_hz
        self.settle, self.hold = 1500 * loop_hz // 1000, 500 * loop_hz // 1000


RUN = Run()
SIDES = (("high", -1), ("low", 1))


def paths(runs, seed):
    """(board file, identified calibration) of a seed."""
    if seed == "sim":
        return os.path.join(ROOT, "boards", "sim.json"), os.path.join(runs, "run-base", "calibration.json")
    return os.path.join(runs, "board-%s.json" % seed), os.path.join(runs, "run-%s" % seed, "calibration.json")


def exact_calibration(board_path, out_path):
    """An exact model calibration of the board, in the firmware's own deformation (see docstring)."""
    import numpy as np

    from boards.sim.actuator import Actuator
    from host.calibration.file import force_table_section
    from testkit import model

    board = json.load(open(board_path))
    w = Actuator(dict(board["actuator"], adc_bits=board["adc_bits"]), 1)
    m1 = w.pots[0].mount_error_mm
    m2 = w.pots[1].mount_error_mm
    xs = np.linspace(-1, 61, 6201)
    d1g = xs + np.array([m1(x) for x in xs])
    dfg = d1g - (xs + np.array([m2(x) for x in xs]))
    kg = float(board["actuator"]["gauge"]["stiffness_n_per_mm"])
    dt = np.unique(np.concatenate([np.linspace(-2.0, 2.0, 81), [-w.d_release, w.d_release]]))
    f = np.array([w.spring_force(v) for v in dt])
    # within 24 N, and no two points in the same um (a knot next to the release point's)
    keep = (np.abs(f) <= 24.0) & np.concatenate([[True], np.diff(dt) > 0.002])
    dt, f = dt[keep], f[keep]
    x2 = RUN.anchor_um / 1000.0 + f / kg
    x1 = x2 + dt
    d1 = x1 + np.array([m1(x) for x in x1])
    dm = d1 - np.interp(d1, d1g, dfg) - (x2 + np.array([m2(x) for x in x2]))
    sec_f = force_table_section(dm, f, (-2.0, 2.0), ("um", "mN"))
    sec_i = force_table_section(f, dm, (-25.0, 25.0), ("mN", "um"))
    model.write_model_calibration(out_path, board=board, force=sec_f, force_inverse=sec_i)
    return out_path




def as_run(runs, seed, board, tmp):
    """The board file as the run used it: bringup's --fix may have raised `oversample` (row.json
    records the value), and 4 reads a step instead of 16 double the deformation's noise. Then
    the diagnostics' changes, if any."""
    row = os.path.join(runs, "run-base" if seed == "sim" else "run-%s" % seed, "row.json")
    oversample = json.load(open(row)).get("oversample") if os.path.exists(row) else None
    oversample = RUN.oversample or oversample
    data = json.load(open(board))
    if RUN.oversample_times:
        oversample = min(64, (oversample or data.get("oversample", 4)) * RUN.oversample_times)
    if (not oversample or data.get("oversample") == oversample) and RUN.noise is None and not RUN.loop_hz:
        return board
    if oversample:
        data["oversample"] = oversample
    if RUN.loop_hz:
        data["loop_hz"] = RUN.loop_hz
    if RUN.noise is not None:
        for pot in ("pot1", "pot2"):
            data["actuator"]["pots"][pot]["noise_lsb"] = RUN.noise
    out = os.path.join(tmp, "board-%s.json" % seed)
    with open(out, "w") as f:
        json.dump(data, f)
    return out


REFIT_ROUNDS = 2  # the guided step's defaults: --rounds 2, --levels 8 (625 duty), --force-range 16
REFIT_LEVEL, REFIT_MAX_DUTY, REFIT_RANGE_MN = 625, 9000, 16000
REFIT_ANCHOR = 45000  # where the run identified F0 (--anchor-mm 45); the steps may then go elsewhere


def refit_calibration(board, cal, out_path, anchor):
    """The run's calibration with its force sections identified again, here and now: the guided
    force step's open-loop points replayed on the board with the run's pots and Df
    (case_force_points_sim at `anchor`, REFIT_ROUNDS rounds a side, each loading until the gauge
    reads 16 N or the spring nears the cavity, each on a freshly started firmware), fitted by the guided step's
    own code (host/guided/force_calibration.py identify and force_sections). What a change to the
    force fit does to the force steps, without a run of the whole chain."""
    import numpy as np

    from host.calibration.file import read_calibration, write_calibration
    from host.guided.force_calibration import CAVITY_NEAR_MM
    from host.guided.force_identification import TAUT_N, force_sections, identify
    from tests.sim.force_cases import case_force_points_sim

    levels = list(range(REFIT_LEVEL, REFIT_MAX_DUTY + 1, REFIT_LEVEL))
    pts = []
    for side, sign in SIDES:
        for _ in range(REFIT_ROUNDS):
            rows = case_force_points_sim(cal, side, levels, anchor=anchor, board_path=board, measured=RUN.measured,
                                         stop_mN=REFIT_RANGE_MN, stop_um=int(CAVITY_NEAR_MM * 1000))
            top = sum(1 for r in rows if r[2])
            duties = levels[:top] + levels[:top - 1][::-1]
            for (d_um, f_mn, loading), duty in zip(rows, duties):
                # s as the guided step gives it: +1 after the force fell
                pts.append((d_um / 1000.0, f_mn / 1000.0, (1 if loading else -1) * -sign, bool(loading), sign * duty))
    d, f, s, loading, duty = (np.array(c) for c in zip(*pts))
    taut = np.abs(f) > TAUT_N
    fit, drive, _ = identify(d[taut], f[taut], s[taut], loading[taut], duty[taut].astype(float))
    doc = read_calibration(cal)
    doc.update(force_sections(fit, drive))
    write_calibration(out_path, doc)
    print("      refit: %d points (%d left out inside the band), F0 %s, h %.3f N" % (
        np.count_nonzero(taut), np.count_nonzero(fit.left_out), "table" if fit.kind == "pwl" else
        "order %d" % fit.order_f, fit.friction_n), flush=True)
    return out_path




def trimmed_calibration(board, cal, out_path, anchor):
    """The calibration with its friction trimmed in closed loop as the guided step does it after
    the force step (host/guided/friction_trim.py): force-mode holds at the trim's targets for a
    16 N range on both sides, at REFIT_ANCHOR, on a freshly started firmware each side; a
    corrected F0 kept only when the check's holds (CHECK_FRACTIONS) read nearer the gauge with
    it than without it, as host/guided/flow.py decides."""
    from host.calibration.file import read_calibration, write_calibration
    from host.guided.friction_trim import (CHECK_FRACTIONS, TRIM_FRACTIONS, keep_correction, rms_error_mn,
                                           trimmed_friction, trimmed_sections)

    doc = read_calibration(cal)
    trim = trimmed_friction(doc["friction"]["friction_n"], side_holds(cal, board, RUN.trim_fractions or TRIM_FRACTIONS, anchor))
    if not RUN.trim_f0:
        trim.f0.why = "--no-f0"
    sections, lines = trimmed_sections(doc, trim)
    if "force" in sections:
        rms = {}
        for name, chosen in (("with", sections), ("without", {"friction": sections["friction"]})):
            write_calibration(out_path, dict(doc, **chosen))
            rms[name] = rms_error_mn(side_holds(out_path, board, CHECK_FRACTIONS, anchor))
        if not keep_correction(rms["with"], rms["without"]):
            sections = {"friction": sections["friction"]}
        lines.append("F0 correction %s: check rms %.0f mN with it, %.0f without" % (
            "kept" if "force" in sections else "NOT kept", rms["with"], rms["without"]))
    doc.update(sections)
    write_calibration(out_path, doc)
    for line in lines:
        print("      trim: " + line, flush=True)
    return out_path


def side_holds(cal, board, fractions, anchor):
    """Force-mode holds at `fractions` of a 16 N range on both sides, as side_holds in
    host/guided/friction_trim.py gives them: {sign: [(magnitude, estimate, gauge)]} (N)."""
    from host.guided.friction_trim import trim_magnitudes
    from tests.sim.force_cases import case_force_steps_sim

    magnitudes = trim_magnitudes(REFIT_RANGE_MN / 1000.0, fractions)
    sides = {}
    for side, sign in SIDES:
        rows = case_force_steps_sim(cal, side, [sign * round(m * 1000) for m in magnitudes], anchor=anchor,
                                    measured=RUN.measured, board_path=board)
        sides[sign] = [(m, sign * est / 1000.0, sign * load / 1000.0) for m, (_, est, load) in zip(magnitudes, rows)]
    return sides


def calibration(runs, seed, exact, tmp):
    board, cal = paths(runs, seed)
    if not os.path.exists(board):
        return board, None
    board = as_run(runs, seed, board, tmp)
    if exact:
        return board, exact_calibration(board, os.path.join(tmp, "exact-%s.json" % seed))
    if not os.path.exists(cal):
        return board, None
    if RUN.refit:
        out = os.path.join(tmp, "refit-%s.json" % seed)
        cal = out if os.path.exists(out) else refit_calibration(board, cal, out, RUN.anchor_um if RUN.at_gauge else REFIT_ANCHOR)
    if RUN.trim:
        out = os.path.join(tmp, "trim-%s.json" % seed)
        cal = out if os.path.exists(out) else trimmed_calibration(board, cal, out, RUN.anchor_um if RUN.at_gauge else REFIT_ANCHOR)
    if RUN.friction:
        cal = friction_replaced(board, cal, os.path.join(tmp, "friction-%s.json" % seed), RUN.friction)
    return board, cal


def friction_replaced(board, cal, out_path, how):
    """Diagnostic: the calibration with its friction h replaced by the board's true Coulomb friction
    ("true") or the force step's identified one before the trim ("identified")."""
    from host.calibration.file import read_calibration, write_calibration

    doc = read_calibration(cal)
    section = doc["friction"]
    h = (json.load(open(board))["actuator"]["block"]["coulomb_n"] if how == "true"
         else section["fit"]["identified_n"])
    section["friction_n"] = h
    section["fixed"] = [int(round(h * 1000))] + list(section["fixed"][1:])
    write_calibration(out_path, doc)
    return out_path


def override_params(pairs):
    """Replace firmware parameter defaults (before any App is made: the controller copies them)."""
    import firmware.protocol as protocol

    names = [row[0] for row in protocol.PARAMS]
    new = {}
    for pair in pairs:
        name, _, value = pair.partition("=")
        if name not in names or not value.lstrip("-").isdigit():
            sys.exit("--param wants NAME=INTEGER with NAME one of: %s (got %r)" % (", ".join(names), pair))
        new[name] = int(value)
    protocol.PARAMS = tuple((row[0], new[row[0]]) + tuple(row[2:]) if row[0] in new else row
                            for row in protocol.PARAMS)


def gauge_anchor_um(runs, seed):
    """Where the guided calibration hooks the gauge on this seed's board (host/guided/stroke.py)."""
    from host.guided import stroke

    board = json.load(open(paths(runs, seed)[0]))
    return round(1000 * stroke.gauge_anchor_mm(stroke.nominal(board, board.get("actuator"))))


def summary(runs, seed, exact, tmp):
    """One line for the seed at the present anchor; returns max(ss, est) over all its steps, %,
    or None when skipped."""
    from tests.sim.force_cases import case_force_steps_sim

    board, cal = calibration(runs, seed, exact, tmp)
    if cal is None:
        print("%-5s skipped: no board or calibration file (%s)" % (seed, board), flush=True)
        return None
    rows = []
    for side, sign in SIDES:
        rows += case_force_steps_sim(cal, side, [sign * t for t in TARGETS], anchor=RUN.anchor_um, settle_ticks=RUN.settle,
                                     hold_ticks=RUN.hold, preload=PRELOAD, board_path=board, measured=RUN.measured)

    def worst(sel):
        ss = max(abs(load - t) / abs(t) * 100 for t, _, load in rows if sel(t))
        es = max(abs(e - load) / max(abs(load), 1) * 100 for t, e, load in rows if sel(t))
        return ss, es
    ss5, es5 = worst(lambda t: abs(t) == 5000)
    ss, es = worst(lambda t: True)
    print("%-5s %-5s anchor %5d  5 N: ss %5.2f %% est %5.2f %% | all: ss %5.2f %% est %5.2f %%"
          % (seed, "exact" if exact else "refit" if RUN.refit else "run", RUN.anchor_um, ss5, es5, ss, es), flush=True)
    return max(ss, es)


IDENT_DUTIES = (300, 600, 900, 1200, 1500)  # open-loop levels: about 1-8 N on these actuators


def ident(runs, seed, tmp):
    """Replays the force identification's open-loop steps (case_force_points_sim, loading then
    unloading, at the anchor) and checks F0 against them: where the block slid, the spring force
    is the load plus h in the direction it slid, so F0(d) - (load + h * slide) should be 0.
    Prints that residual's range per side for the identified and the exact calibration (mN)."""
    from firmware.measurement import Measurement
    from tests.sim.firmware_cases import load_calibration
    from tests.sim.force_cases import case_force_points_sim

    board, cal_run = calibration(runs, seed, False, tmp)
    _, cal_exact = calibration(runs, seed, True, tmp)
    if cal_run is None:
        print("%-5s skipped: no board or calibration file (%s)" % (seed, board), flush=True)
        return
    m_run = Measurement(load_calibration(cal_run))
    m_exact = Measurement(load_calibration(cal_exact))
    h = m_run.fric
    parts = []
    for side, _sign in SIDES:
        rows = case_force_points_sim(cal_run, side, list(IDENT_DUTIES), anchor=RUN.anchor_um, board_path=board)
        res = {"identified": [], "exact": []}
        prev = None
        for d, load, _loading in rows:
            if prev is not None and load != prev:  # the block slid (a stuck block keeps its load)
                slide = 1 if load > prev else -1
                for name, m in (("identified", m_run), ("exact", m_exact)):
                    f0 = m.force_eval(d + m.st[16], m.k_force)
                    res[name].append(f0 - (load + slide * h))
            prev = load
        if not res["identified"]:
            parts.append("%s: no points (the block cannot be hooked at that anchor on this stroke)" % side)
            continue
        parts.append("%s: identified %+d..%+d, exact %+d..%+d (%d points)" % (
            side, min(res["identified"]), max(res["identified"]), min(res["exact"]), max(res["exact"]),
            len(res["identified"])))
    print("%-5s anchor %5d  F0(d) - (load + h * slide), mN: %s" % (seed, RUN.anchor_um, "; ".join(parts)), flush=True)


def trace(runs, seed, side, exact, tmp):
    import boards.sim.machine as sim
    import tests.sim.force_cases as fc
    from tests.sim.firmware_cases import _run

    board, cal = calibration(runs, seed, exact, tmp)
    if cal is None:
        sys.exit("no board or calibration file for seed %s under %s" % (seed, runs))
    h = json.load(open(board))["actuator"]["block"]["coulomb_n"] * 1000
    app, world, sign = fc._hooked_on_side(cal, side, RUN.anchor_um, 200, board)
    app.set_mode("force")
    app.set_target(sign * PRELOAD)
    _run(app, 500)
    print("seed %s side %s (%s calibration), block friction h = %.0f mN; mN, in load units"
          % (seed, side, "exact" if exact else "refit" if RUN.refit else "run", h))
    print("target  spring_ext  F0filt_ext    gap  est-load  spring_sd")
    prev = PRELOAD
    for t in TARGETS:
        app.set_target(sign * t)
        s = 1 if t > prev else -1
        sp_ext = f0_ext = None
        est = load = 0.0
        held = []
        for k in range(RUN.settle + RUN.hold):
            sim.run_ticks(1)
            app.heartbeat()
            m = app.ctrl.meas
            sp = sign * world.spring_force_n * 1000.0
            f0 = sign * (m.fs32 >> 5)
            if sp_ext is None or s * sp > s * sp_ext:
                sp_ext = sp
            if f0_ext is None or s * f0 > s * f0_ext:
                f0_ext = f0
            if k >= RUN.settle:
                est += sign * m.force
                load += -sign * world.external_force_n * 1000.0
                held.append(sp)
        mean = sum(held) / RUN.hold
        sd = (sum((v - mean) ** 2 for v in held) / RUN.hold) ** 0.5
        print("%6d  %10.0f  %10.0f  %5.0f  %8.0f  %9.0f" % (t, sp_ext, f0_ext, sp_ext - f0_ext, (est - load) / RUN.hold, sd))
        prev = t
    app.shutdown()


def print_spread(per_seed):
    """Per actuator, the worst step over its anchors: mean, standard deviation and range. Anchors
    a few tens of um apart keep the pots' local error and change only the noise's realisation, so
    the spread is the part of a verdict that chance decides (docs/robustness.md)."""
    for seed, ws in per_seed.items():
        mean = sum(ws) / len(ws)
        sd = (sum((w - mean) ** 2 for w in ws) / len(ws)) ** 0.5
        print("%-5s worst step over %d anchors: mean %.2f %%, sd %.2f %%, %.2f-%.2f %%, within 2 %% at %d"
              % (seed, len(ws), mean, sd, min(ws), max(ws), sum(w <= 2.0 for w in ws)), flush=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("seeds", nargs="*", default=["1000", "1001", "1005", "1006", "1007", "sim"])
    ap.add_argument("--runs", default=os.path.join(ROOT, "out", "robF"),
                    help="a robustness run's output: board-SEED.json, run-SEED/ (default out/robF)")
    ap.add_argument("--exact", action="store_true", help="exact model calibration instead of the identified one")
    ap.add_argument("--trace", nargs=2, metavar=("SEED", "SIDE"), help="per-step extremes for one seed and side")
    ap.add_argument("--refit", action="store_true",
                    help="identify the force sections again by replaying the guided force step (the run's pots and Df kept)")
    ap.add_argument("--trim", action="store_true",
                    help="trim the calibration's friction in closed loop first, as the guided step does after the force step")
    ap.add_argument("--no-f0", action="store_true", help="with --trim: trim h only, leave F0 as identified")
    ap.add_argument("--trim-fractions", metavar="F,F,...",
                    help="with --trim: the trim's targets as fractions of the range (default friction_trim.TRIM_FRACTIONS)")
    ap.add_argument("--ident", action="store_true",
                    help="check F0 of both calibrations against a replay of the force identification")
    ap.add_argument("--anchor", type=int, default=45000, help="gauge anchor, um (default 45000)")
    ap.add_argument("--anchors", help="several anchors, um, comma-separated (a tally over all cases)")
    ap.add_argument("--at-gauge", action="store_true",
                    help="--anchor/--anchors are offsets, um, from each board's own gauge anchor (75 %% along its "
                         "stroke, where the guided force step and the paper's force runs hook it)")
    ap.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                    help="diagnostic: a firmware parameter's default replaced (repeatable)")
    ap.add_argument("--oversample", type=int, help="diagnostic: reads per step on every board")
    ap.add_argument("--oversample-times", type=int, metavar="K",
                    help="diagnostic: the run's own reads per step times K (at most 64)")
    ap.add_argument("--noise", type=float, metavar="LSB", help="diagnostic: both pots' noise, LSB")
    ap.add_argument("--friction", choices=("true", "identified"),
                    help="diagnostic: the calibration's friction h replaced by the board's true one or the force step's "
                         "identified one (before the trim)")
    ap.add_argument("--filter-shift", type=int, metavar="N",
                    help="diagnostic: the estimate's average over 2**N steps (measurement.filter_shift; 6 at 1 kHz)")
    ap.add_argument("--loop-hz", type=int, metavar="HZ", help="every board's loop rate (settle and hold keep their seconds)")
    ap.add_argument("--true-load", action="store_true",
                    help="diagnostic: score (and trim, refit) against the simulator's true load instead of the gauge's "
                         "readings, which is what a bench has")
    a = ap.parse_args()
    RUN.measured = not a.true_load
    RUN.anchor_um = a.anchor
    try:
        anchors = [int(v) for v in a.anchors.split(",")] if a.anchors else [a.anchor]
    except ValueError:
        sys.exit("--anchors wants um values separated by commas, e.g. 44000,45000,46000")
    RUN.refit = a.refit
    RUN.trim = a.trim
    RUN.trim_f0 = not a.no_f0
    if a.trim_fractions:
        RUN.trim_fractions = tuple(float(v) for v in a.trim_fractions.split(","))
    RUN.at_gauge = a.at_gauge
    RUN.oversample = a.oversample
    RUN.oversample_times = a.oversample_times
    RUN.noise = a.noise
    RUN.friction = a.friction
    if a.loop_hz:
        RUN.at_rate(a.loop_hz)
    override_params(a.param)
    if a.filter_shift is not None:  # before any App is made: Measurement asks it at construction
        import firmware.measurement as measurement

        measurement.filter_shift = lambda loop_hz: a.filter_shift
    if not os.path.isdir(a.runs):
        sys.exit("robustness data directory not found: %s (give it with --runs DIR)" % a.runs)
    os.chdir(ROOT)
    with tempfile.TemporaryDirectory() as tmp:
        if a.trace:
            if a.trace[1] not in ("high", "low"):
                sys.exit("SIDE is high or low")
            RUN.anchor_um = a.anchor + (gauge_anchor_um(a.runs, a.trace[0]) if a.at_gauge else 0)
            trace(a.runs, a.trace[0], a.trace[1], a.exact, tmp)
        elif a.ident:
            for anchor in anchors:
                for seed in a.seeds:
                    RUN.anchor_um = anchor + (gauge_anchor_um(a.runs, seed) if a.at_gauge else 0)
                    ident(a.runs, seed, tmp)
        else:
            worst = []
            per_seed = {}
            for anchor in anchors:
                for seed in a.seeds:
                    RUN.anchor_um = anchor + (gauge_anchor_um(a.runs, seed) if a.at_gauge else 0)
                    w = summary(a.runs, seed, a.exact, tmp)
                    if w is not None:
                        worst.append(w)
                        per_seed.setdefault(seed, []).append(w)
            if len(anchors) > 1:
                print_spread(per_seed)
            if worst:
                changed = a.param + (["oversample=%d" % a.oversample] if a.oversample else []) + \
                    (["oversample x%d" % a.oversample_times] if a.oversample_times else []) + \
                    (["loop %d Hz" % a.loop_hz] if a.loop_hz else []) + \
                    (["noise=%g LSB" % a.noise] if a.noise is not None else []) + \
                    (["friction h %s" % a.friction] if a.friction else []) + \
                    (["estimate over 2**%d steps" % a.filter_shift] if a.filter_shift is not None else []) + \
                    (["scored against the TRUE load"] if a.true_load else ["scored against the gauge's readings"])
                print("tally (%s calibration%s%s): %d of %d cases within 2 %% at every step; mean worst %.2f %%, "
                      "max %.2f %%" % ("exact" if a.exact else "re-identified" if a.refit else "identified",
                                       ", friction trimmed" if a.trim else "",
                                       ", " + ", ".join(changed) if changed else "", sum(w <= 2.0 for w in worst),
                                       len(worst), sum(worst) / len(worst), max(worst)), flush=True)


if __name__ == "__main__":
    main()
