"""Where the offline force steps' errors come from, and what they imply for a whole run.

    .venv/bin/python bench/bench_force_error_budget.py --runs DIR [--anchors UM,UM] [--loop-hz HZ]
        [--oversample N] [--oversample-times K] [--targets MN,MN,...] [--rows] [--refit [--trim]] SEED...

The same steps as bench/bench_force_steps_offline.py (5, 10, 15, 10, 5 N a side after a 0.5 N
preload, or --targets' magnitudes, e.g. the held-out steps' 2-7 N; settled 1.5 s, measured 0.5 s;
the real firmware App on the simulated actuator on
CPython, each board's identified calibration from the robustness run in DIR, or with --refit
the force step replayed offline on the run's pots, Df and ladder and fitted again (--trim: and
trimmed; what a change to the force step or its fit does, without a fresh run), the gauge hooked
at --anchors um from each board's own anchor), but each hold's error is split with the
simulator's true forces, which no bench has (a diagnostic, judged against the true load):

    estimate - load = (filtered F0 - true spring)     the calibration's error: F0(d) against the spring
                    + (true spring - load)            the friction the stuck block holds at the end
                    + (estimate - filtered F0)        the play operator's friction term in the estimate

The firmware drives the spring past the target to the friction band's edge (the block slides to
the target) and then back to the target, so at rest its estimate is about F0 itself and the
load is off by what the block still holds. It prints the rms of each part per step of the
sequence, the share of steps beyond 2 %, and what that share makes of a run: the paper
experiment judges 12 held-out steps (host/experiments/held_out.py), all of which must be within
2 %, so with a share p of steps missing, a run meets the force target with about (1 - p)**12,
and issue 26's 90 % of runs needs p below 0.9 %. Steps taken as independent (they are not
quite: an actuator's calibration error is shared by its steps).
"""

import argparse
import os
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.join(ROOT, "bench"))

import offline_force_rig as offline  # noqa: E402  (the same actuators, calibrations and steps)

HELD_OUT_STEPS = 12  # host/experiments/held_out.py: LOADING + UNLOADING a side, two sides
PARTS = ("estimate - load", "calibration", "friction held", "friction term")


def phases(targets):
    """A name for each step of the sequence `targets` (mN magnitudes): "5 N loading", ..."""
    out, peak = [], 0
    for t in targets:
        out.append("%g N %s" % (t / 1000.0, "loading" if t > peak else "unloading"))
        peak = max(peak, t)
    return tuple(out)


def holds(runs, seed, anchor_offset, tmp):
    """Per side and step: (target mN, load mN, the three parts mN), the hold's means."""
    import boards.sim.machine as sim
    from tests.sim.firmware_cases import _run
    from tests.sim.force_cases import _hooked_on_side

    own = offline.gauge_anchor_um(runs, seed)
    offline.RUN.anchor_um = own  # where --refit and --trim replay the guided steps: where the run hooked the gauge
    board, cal = offline.calibration(runs, seed, False, tmp)
    if cal is None:
        return []
    anchor = anchor_offset + own
    out = []
    for side, _ in offline.SIDES:
        app, world, sign = _hooked_on_side(cal, side, anchor, 200, board)
        app.set_mode("force")
        app.set_target(sign * offline.PRELOAD)
        _run(app, 500)
        for target in offline.RUN.targets:
            app.set_target(sign * target)
            est = f0 = spring = load = 0.0
            for k in range(offline.RUN.settle + offline.RUN.hold):
                sim.run_ticks(1)
                app.heartbeat()
                if k >= offline.RUN.settle:
                    m = app.ctrl.meas
                    est += sign * m.force
                    f0 += sign * (m.fs32 >> 5)
                    spring += sign * world.spring_force_n * 1000.0
                    load += -sign * world.external_force_n * 1000.0
            n = offline.RUN.hold
            est, f0, spring, load = est / n, f0 / n, spring / n, load / n
            out.append((seed, side, target, load, (est - load, f0 - spring, spring - load, est - f0)))
        app.shutdown()
    return out


def rms(values):
    return (sum(v * v for v in values) / len(values)) ** 0.5 if values else float("nan")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("seeds", nargs="+")
    ap.add_argument("--runs", required=True, help="a robustness run's output: board-SEED.json, run-SEED/")
    ap.add_argument("--anchors", default="0", help="um from each board's own gauge anchor, comma-separated (default 0)")
    ap.add_argument("--loop-hz", type=int, metavar="HZ", help="every board's loop rate (settle and hold keep their seconds)")
    ap.add_argument("--oversample", type=int, metavar="N", help="every board read N times a step (default: as its run was)")
    ap.add_argument("--oversample-times", type=int, metavar="K", help="the run's own reads per step times K (at most 64)")
    ap.add_argument("--targets", metavar="MN,MN,...", help="the step sequence's magnitudes in mN (default 5000,10000,15000,10000,5000)")
    ap.add_argument("--rows", action="store_true", help="print every hold's split as well")
    ap.add_argument("--refit", action="store_true", help="identify the force sections again first, replaying the guided "
                    "force step on the run's ladder (bench/offline_force_rig.py refit_calibration; the gauge read true)")
    ap.add_argument("--trim", action="store_true", help="then trim h and F0 in closed loop as the guided step does")
    a = ap.parse_args()
    if not os.path.isdir(a.runs):
        sys.exit("robustness data directory not found: %s" % a.runs)
    try:
        anchors = [int(v) for v in a.anchors.split(",")]
    except ValueError:
        sys.exit("--anchors wants um values separated by commas, e.g. -1000,0,1000")
    run = offline.RUN
    run.at_gauge = True
    if a.targets:
        try:
            run.targets = tuple(int(v) for v in a.targets.split(","))
        except ValueError:
            sys.exit("--targets wants mN magnitudes separated by commas, e.g. 2500,4000,6500,4500,3000")
    run.refit, run.trim = a.refit, a.trim
    run.oversample = a.oversample
    run.oversample_times = a.oversample_times
    if a.loop_hz:
        run.at_rate(a.loop_hz)
    os.chdir(ROOT)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for anchor in anchors:
            for seed in a.seeds:
                got = holds(a.runs, seed, anchor, tmp)
                rows += got
                if a.rows:
                    for s, side, t, load, parts in got:
                        print("%s %-4s %5d mN: load %+.2f %%; " % (s, side, t, 100.0 * (load / t - 1))
                              + ", ".join("%s %+.0f" % (n, v) for n, v in zip(PARTS, parts)), flush=True)
    if not rows:
        sys.exit("no actuator with a calibration under %s" % a.runs)
    print("%d holds (%d actuators x %d anchors x 2 sides x %d steps), loop %s Hz%s, mN rms (mean) of each part:"
          % (len(rows), len(a.seeds), len(anchors), len(run.targets), a.loop_hz or "the boards'",
             (", %d reads a step" % a.oversample if a.oversample else "")
             + (", the run's reads x%d" % a.oversample_times if a.oversample_times else "")
             + (", force sections refitted offline" + (" and trimmed" if a.trim else "") if a.refit else
                ", trimmed again offline" if a.trim else "")))
    print("| step | " + " | ".join(PARTS) + " | beyond 2 % |")
    print("| --- " * (len(PARTS) + 2) + "|")
    steps = len(run.targets)
    for k, phase in enumerate(phases(run.targets) + ("all",)):
        sel = [r for i, r in enumerate(rows) if phase == "all" or i % steps == k]
        cells = ["%.0f (%+.0f)" % (rms([r[4][j] for r in sel]), sum(r[4][j] for r in sel) / len(sel)) for j in range(len(PARTS))]
        miss = sum(abs(r[3] / r[2] - 1) > 0.02 for r in sel)
        print("| %s | %s | %d of %d |" % (phase, " | ".join(cells), miss, len(sel)))
    p = sum(abs(r[3] / r[2] - 1) > 0.02 for r in rows) / len(rows)
    print("share of steps beyond 2 %%: %.1f %%; a run of %d held-out steps all within 2 %%: about %.0f %% of runs "
          "(steps taken as independent); 90 %% of runs needs a share below %.1f %%"
          % (100 * p, HELD_OUT_STEPS, 100 * (1 - p) ** HELD_OUT_STEPS, 100 * (1 - 0.9 ** (1.0 / HELD_OUT_STEPS))))


if __name__ == "__main__":
    main()
