"""How right the force step's F0 is at the gauge's anchor: today's fit of a run's recorded force
points, beside the fit that run made, against the simulated spring.

A robustness run (bench/bench_robustness.py) keeps, per actuator, the force step's points in the
order taken (run-SEED/force-points.csv) and the fit it made of them (results.json, force_fit:
the identified F0 and h, before the closed-loop trim). This bench fits the same points again
with today's host/fitting/force.py and scores both fits the same way, with no simulation run:

- the block held at the gauge's anchor (where the guided step hooks it, in the firmware's D2),
  moved by F / gauge stiffness as the fibre stretches, the nut a true deformation further on,
  for each force F of --forces: the true spring force F is the simulator's own spring;
- the deformation the firmware measures there: the run's calibration (its pots and Df; the
  force sections play no part) at the simulated pots' noise-free codes, linear between codes
  (what the pots' noise averages to);
- the error of each fit, F0(measured d) - F, in mN, and its h (as identified, before the trim)
  minus the board's true Coulomb friction.

It judges the identification alone: the trim, the F0 correction and the loop come after it. A fit
change made against these recorded points makes them development data.

Call (from the repository root, the venv's python):
    python bench/bench_force_fit_replay.py [--forces N,N,...] RUNS_DIR [RUNS_DIR ...]
RUNS_DIR a robustness run's --out directory (board-SEED.json and run-SEED/ for each actuator).

What it prints: per actuator, h - true h and the error at each force for the run's fit ("run")
and today's ("now", with how many points it left out inside the friction band); then the rms
over the actuators at each force, the rms over all, and the mean |error| at |F| <= 4 N.
"""

import argparse
import csv
import glob
import json
import math
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

FORCES_N = (-14, -10, -6, -4, -3, -2, 2, 3, 4, 6, 10, 14)
SMALL_N = 4.0


def true_deformation_mm(world, force_n):
    """The spring's deformation (mm) at which the simulated spring pushes `force_n`."""
    lo, hi = -3.0, 3.0
    for _ in range(60):
        mid = (lo + hi) / 2
        if world.spring_force(mid) < force_n:
            lo = mid
        else:
            hi = mid
    return (lo + hi) / 2


def measured_deformations_mm(board, calibration_path, anchor_mm, forces):
    """The firmware's deformation d (mm) with the block at the anchor (in its D2) and the spring
    pushing each force, through the run's pots and Df, linear between the pots' codes."""
    from boards.sim.actuator import Actuator
    from firmware import measurement
    from firmware.calibration import load_calibration

    meas = measurement.Measurement(load_calibration(calibration_path))
    world = Actuator(dict(board["actuator"], adc_bits=board["adc_bits"]), 1)
    full = world.full_code
    gauge_n_per_mm = float(board["actuator"]["gauge"]["stiffness_n_per_mm"])

    def d2_mm(block_mm):
        meas.update(full // 2, int(round(world.pots[1].fraction(block_mm) * full)))
        return meas.st[measurement.D2] / 1000.0

    lo, hi = anchor_mm - 6.0, anchor_mm + 6.0  # the end-stop frame shifts D2 by a few mm at most
    for _ in range(50):
        mid = (lo + hi) / 2
        if d2_mm(mid) < anchor_mm:
            lo = mid
        else:
            hi = mid
    block0 = (lo + hi) / 2
    out = []
    for force in forces:
        block = block0 + force / gauge_n_per_mm
        codes = (world.pots[0].fraction(block + true_deformation_mm(world, force)) * full,
                 world.pots[1].fraction(block) * full)
        value = 0.0
        for c1, w1 in _between(codes[0]):
            for c2, w2 in _between(codes[1]):
                meas.update(c1, c2)
                value += w1 * w2 * meas.st[measurement.DEFL]
        out.append(value / 1000.0)
    return out


def _between(code):
    """The two whole codes about `code`, weighted for linear interpolation."""
    low = math.floor(code)
    return ((low, 1.0 - (code - low)), (low + 1, code - low))


def run_fit(results, calibration):
    """F0 (a function of d, mm -> N) and h of the fit a run made: its results.json force_fit (the
    identified F0) and the h its force step identified (the calibration's friction section keeps
    it as `identified_n` once the trim has replaced it)."""
    import numpy as np

    from host.fitting.force import table_value

    fit = results["force_fit"]
    friction = calibration["payload"]["friction"]
    h = (friction.get("fit") or {}).get("identified_n", friction["friction_n"])
    if fit.get("kind") == "pwl":
        kx, ky = np.array(fit["knots_d"]), np.array(fit["knots_f"])
        return (lambda d: table_value(d, kx, ky)), h
    return (lambda d: np.polyval(fit["coeffs_f"], d)), h


def todays_fit(points_path):
    """Today's fit of a run's recorded force points: (F0 function, h, points left out)."""
    import numpy as np

    from host.fitting.force import fit_force
    from host.guided.force_identification import TAUT_N

    rows = list(csv.DictReader(open(points_path)))
    d, f, s = (np.array([float(r[k]) for r in rows]) for k in ("d_mm", "force_n", "s"))
    loading = np.array([int(r["loading"]) for r in rows], dtype=bool)
    taut = np.abs(f) > TAUT_N
    fit = fit_force(d[taut], f[taut], s[taut], "auto", friction=True, loading=loading[taut])
    return fit.f0, fit.friction_n, int(np.count_nonzero(fit.left_out))


def main():
    import numpy as np

    from bench.offline_force_rig import gauge_anchor_um

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("runs", nargs="+", help="robustness run output directories")
    ap.add_argument("--forces", default=",".join(str(f) for f in FORCES_N), help="N, comma-separated")
    a = ap.parse_args()
    forces = [float(x) for x in a.forces.split(",")]
    errors = {"run": [], "now": []}
    for runs in a.runs:
        for points in sorted(glob.glob(os.path.join(runs, "run-*", "force-points.csv"))):
            run_dir = os.path.dirname(points)
            seed = run_dir.rsplit("-", 1)[-1]
            board_path = os.path.join(runs, "board-%s.json" % seed)
            results_path = os.path.join(run_dir, "results.json")
            if not (os.path.exists(board_path) and os.path.exists(results_path)):
                continue
            board = json.load(open(board_path))
            true_h = float(board["actuator"]["block"]["coulomb_n"])
            d = np.array(measured_deformations_mm(board, os.path.join(run_dir, "calibration.json"),
                                                  gauge_anchor_um(runs, seed) / 1000.0, forces))
            f0_run, h_run = run_fit(json.load(open(results_path)), json.load(open(os.path.join(run_dir, "calibration.json"))))
            f0_now, h_now, left_out = todays_fit(points)
            parts = []
            for name, f0, h in (("run", f0_run, h_run), ("now", f0_now, h_now)):
                e = 1000.0 * (f0(d) - np.array(forces))
                errors[name].append(e)
                parts.append("%s: h %+4.0f | %s" % (name, 1000 * (h - true_h), " ".join("%+4.0f" % x for x in e)))
            print("%s  %s  (now left out %d)" % (seed, "   ".join(parts), left_out), flush=True)
    small = [i for i, f in enumerate(forces) if abs(f) <= SMALL_N]
    print("F0 error at the gauge's anchor, mN, over %d actuators; forces %s N" % (
        len(errors["run"]), " ".join("%+g" % f for f in forces)))
    for name, label in (("run", "the runs' own fits"), ("now", "today's fit")):
        e = np.array(errors[name])
        if not len(e):
            continue
        print("%-18s rms by force %s | rms %.0f, mean |e| at |F| <= %g N %.0f" % (
            label, " ".join("%.0f" % x for x in np.sqrt(np.mean(e ** 2, axis=0))), np.sqrt(np.mean(e ** 2)), SMALL_N,
            np.mean(np.abs(e[:, small]))))


if __name__ == "__main__":
    main()
