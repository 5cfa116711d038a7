"""Offline force steps against the gauge on simulated actuators (lsea-kit issue 11).

What it runs: tests/sim/force_cases.py case_force_steps_sim -- the real firmware App on the
simulated actuator, advanced with run_ticks on CPython (no real time, deterministic) -- with the
bench's steps: 5, 10, 15, 10, 5 N on each side of the gauge ("high" and "low"), after a 0.5 N
preload, each step settled 1.5 s (1500 ticks) then measured 0.5 s (500 ticks).

Which actuators: for each SEED, the board file RUNS/board-SEED.json and the calibration the
robustness run identified for it, RUNS/run-SEED/calibration.json; with seed "sim", the
repository's boards/sim.json and RUNS/run-base/calibration.json (skipped if that file is missing).
With --refit the run's force sections are identified again by replaying the guided force step
(bench/offline_force_rig.py refit_calibration: the run's pots and Df, the fit of today's code),
so that a change to the force fit can be judged on the same actuators without a robustness run.
With --trim the calibration's friction is first trimmed in closed loop, as the guided calibration
does after the force step (offline_force_rig.trimmed_calibration, host/guided/friction_trim.py).
A tally repeats exactly, with --refit and --trim too. (Until 2026-11-27 those two did not: the
force fit's fit_pwl called scipy's least_squares(method="lm"), whose C MINPACK in scipy 1.15-1.17
reads past the end of its Jacobian, so the knots depended on memory; host/fitting/
levenberg_marquardt.py says more.)
With --exact the identified calibration is replaced by an exact model calibration of that board
(testkit/model.py write_model_calibration): F0 tabled against the deformation the firmware
measures (the pots' mount errors and the Df travel included, the block where the gauge holds it
for that force) and the friction section equal to the board's true coulomb_n; with --trim too,
that friction is then trimmed in closed loop as the guided calibration trims its own (what is left
is the loop's share, without the calibration's). The pot tables span the board's own stroke (a
drawn board's is 40-80 mm; until stop 41 they spanned 0-60 mm, and --exact on drawn boards read
nonsense), and each knot pairs a position with its unrounded code (until stop 43 the rounded one,
up to half a code off: the 'exact' deformation was 10-20 um wrong in places, 0.1-0.25 N, and the
exact figures of stops 41 and 42 carry that). --exact --refit keeps the exact pots and Df and
identifies the force sections again as --refit does: the force identification's share alone.

Call (from the repository root, the venv's python):
    python bench/bench_force_steps_offline.py [--runs DIR] [--exact] [--refit] [--trim] [--anchors UM,UM] [SEED ...]
    python bench/bench_force_steps_offline.py [--runs DIR] [--exact] --trace SEED SIDE
    python bench/bench_force_steps_offline.py [--runs DIR] --ident [--anchors UM,UM] [SEED ...]
--anchor UM moves the gauge anchor (default 45000 um of D2, where the guided force step and the
paper's force runs hook it; the fibre is hooked from where the block is, as the virtual rig does):
the same board at another block position, another realisation of the noise and the friction's
stick states, to see how much a result moves;
--targets MN,MN,... replaces the paper's 5, 10, 15, 10, 5 N with another sequence (the held-out
draws go down to about 2.5 N); the per-seed line's first column is then its first step;
--anchors UM,UM,... runs each seed at several and prints a tally over all (seed, anchor) cases,
and per seed the mean, spread and range of its worst step over the anchors.
Diagnostics (each changes what is run, and says so in the tally line):
    --param NAME=VALUE   a firmware parameter's default replaced (protocol.PARAMS), e.g. kp_force=1280
    --oversample N       every board read N times a step (the run's own value is used otherwise)
    --oversample-times K the run's own reads a step times K, at most 64 (the run's own may be
                         bringup's 16 already: --oversample N says how many a board makes)
    --noise LSB          both pots' noise set to LSB (what the loop does with quieter pots)
    --friction true|identified   the calibration's friction h replaced by the board's true one or
                         the force step's identified one (what the trim changes)
    --filter-shift N     the estimate's average over 2**N steps instead of measurement.filter_shift's
    --loop-hz HZ         every board's loop rate (CircuitPython's 250 Hz); settle and hold keep
                         their seconds
    --spring true|observer   the play operator fed the simulator's true spring force, or an
                         observer's driven by the motor voltage with the board's true constants
                         (bench/spring_diagnostics.py; --drive-scale K makes its motor constant
                         wrong by K, --bias-hz HZ adds a bias state); use with --filter-shift 0
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
import contextlib
import json
import os
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import spring_diagnostics  # noqa: E402
from offline_force_rig import (PRELOAD, ROOT, RUN, SIDES, calibration, gauge_anchor_um,  # noqa: E402
                               override_params)

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
        rows += case_force_steps_sim(cal, side, [sign * t for t in RUN.targets], anchor=RUN.anchor_um, settle_ticks=RUN.settle,
                                     hold_ticks=RUN.hold, preload=PRELOAD, board_path=board, measured=RUN.measured)

    def worst(sel):
        ss = max(abs(load - t) / abs(t) * 100 for t, _, load in rows if sel(t))
        es = max(abs(e - load) / max(abs(load), 1) * 100 for t, e, load in rows if sel(t))
        return ss, es
    first = RUN.targets[0]  # the smallest step, 5 N in the paper's sequence
    ss5, es5 = worst(lambda t: abs(t) == first)
    ss, es = worst(lambda t: True)
    print("%-5s %-5s anchor %5d  %g N: ss %5.2f %% est %5.2f %% | all: ss %5.2f %% est %5.2f %%"
          % (seed, "exact" if exact else "refit" if RUN.refit else "run", RUN.anchor_um, first / 1000.0, ss5, es5, ss, es),
          flush=True)
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
    print("target  spring_ext  F0filt_ext    gap  est-load  spring_sd  load-target")
    prev = PRELOAD
    for t in RUN.targets:
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
        print("%6d  %10.0f  %10.0f  %5.0f  %8.0f  %9.0f  %11.0f" % (t, sp_ext, f0_ext, sp_ext - f0_ext, (est - load) / RUN.hold, sd,
                                                            load / RUN.hold - t))
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
                    help="identify the force sections again by replaying the guided force step (the run's pots and Df kept; "
                         "with --exact, the exact ones)")
    ap.add_argument("--trim", action="store_true",
                    help="trim the calibration's friction in closed loop first, as the guided step does after the force step")
    ap.add_argument("--no-f0", action="store_true", help="with --trim: trim h only, leave F0 as identified")
    ap.add_argument("--trim-fractions", metavar="F,F,...",
                    help="with --trim: the trim's targets as fractions of the range (default friction_trim.TRIM_FRACTIONS)")
    ap.add_argument("--ident", action="store_true",
                    help="check F0 of both calibrations against a replay of the force identification")
    ap.add_argument("--targets", metavar="MN,MN,...",
                    help="the step sequence's magnitudes, mN (default 5000,10000,15000,10000,5000, the paper's)")
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
    ap.add_argument("--spring", choices=("true", "observer"),
                    help="diagnostic: the estimate's play operator fed the simulator's true spring force, or a "
                         "model-based observer's with the board's true motor constants (bench/spring_diagnostics.py); "
                         "pair with --filter-shift 0")
    ap.add_argument("--drive-scale", type=float, default=1.0, metavar="K",
                    help="with --spring observer: the observer's motor force per volt times K (its cost when wrong)")
    ap.add_argument("--bias-hz", type=float, default=0.0, metavar="HZ",
                    help="with --spring observer: also estimate a bias force (what the model's drive misses), its "
                         "pole at about HZ (0: none)")
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
    if a.spring and a.loop_hz and a.loop_hz != 1000:
        sys.exit("--spring observer models one step as 1 ms: use it at the 1 kHz loop (no --loop-hz)")
    if a.targets:
        RUN.targets = tuple(int(v) for v in a.targets.split(","))
    if not os.path.isdir(a.runs):
        sys.exit("robustness data directory not found: %s (give it with --runs DIR)" % a.runs)
    os.chdir(ROOT)
    with tempfile.TemporaryDirectory() as tmp, \
            (spring_diagnostics.feeding(a.spring, a.drive_scale, a.bias_hz) if a.spring else contextlib.nullcontext()):
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
                changed = a.param + (["steps %s mN" % a.targets] if a.targets else []) + \
                    (["oversample=%d" % a.oversample] if a.oversample else []) + \
                    (["oversample x%d" % a.oversample_times] if a.oversample_times else []) + \
                    (["loop %d Hz" % a.loop_hz] if a.loop_hz else []) + \
                    (["noise=%g LSB" % a.noise] if a.noise is not None else []) + \
                    (["friction h %s" % a.friction] if a.friction else []) + \
                    (["estimate over 2**%d steps" % a.filter_shift] if a.filter_shift is not None else []) + \
                    (["play operator fed the %s spring force%s" % (
                        "TRUE" if a.spring == "true" else "observer's",
                        ("" if a.spring != "observer" else
                         (" (drive x%g)" % a.drive_scale if a.drive_scale != 1.0 else "") +
                         (" (bias pole %g Hz)" % a.bias_hz if a.bias_hz else "")))]
                     if a.spring else []) + \
                    (["scored against the TRUE load"] if a.true_load else ["scored against the gauge's readings"])
                print("tally (%s calibration%s%s): %d of %d cases within 2 %% at every step; mean worst %.2f %%, "
                      "max %.2f %%" % ("exact" if a.exact else "re-identified" if a.refit else "identified",
                                       ", friction trimmed" if a.trim else "",
                                       ", " + ", ".join(changed) if changed else "", sum(w <= 2.0 for w in worst),
                                       len(worst), sum(worst) / len(worst), max(worst)), flush=True)


if __name__ == "__main__":
    main()
