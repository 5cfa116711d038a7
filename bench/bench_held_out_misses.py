"""Where the held-out force misses of robustness runs sit: by drawn force, the estimate's error
against the gauge and the share of steps beyond the force target, over every actuator of the
given runs (no simulation run: their results.json only).

A robustness run (bench/bench_robustness.py) keeps each actuator's results in
RUNS_DIR/run-SEED/results.json; its held-out force steps (host/experiments/held_out.py) carry the
target, the gauge's reading and the firmware's estimate. A step misses when its steady-state or
estimation error is beyond TARGETS["force_pct"], as host/experiments/targets.py judges it.

Call (from the repository root, the venv's python):
    python bench/bench_held_out_misses.py RUNS_DIR [RUNS_DIR ...]

What it prints: per band of drawn force, the steps, the rms of estimate - gauge (mN, in the
direction of the load), the rms of estimate - target (the loop's own end), and how many steps
missed; then the totals; then estimate - gauge by a step's place in its side's sequence (the
first loading step, the last unloading one, the others), and how much of it a group of steps
shares (one actuator, side and direction: a calibration's or a friction's error) against what
each step has of its own.
"""

import glob
import json
import math
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from host.experiments.targets import TARGETS  # noqa: E402

BANDS_N = (2.0, 3.0, 4.5, 7.0, 10.0, 17.0)


def held_out_steps(runs_dirs):
    """(|target| N, estimate - gauge mN, estimate - target mN, missed, group, place) of every
    held-out force step; group: (run, side, phase); place: "first loading", "last unloading" or
    "other loading" / "other unloading" in its side's sequence."""
    out = []
    for d in runs_dirs:
        for path in sorted(glob.glob(os.path.join(d, "run-*", "results.json"))):
            with open(path) as f:
                r = json.load(f)
            rows = (r.get("held_out") or {}).get("forces") or []
            for x in rows:
                sign = 1.0 if x["target"] > 0 else -1.0
                same = [y for y in rows if y["side"] == x["side"] and y["phase"] == x["phase"]]
                if x["phase"] == "loading":
                    place = "first loading" if same[0] is x else "other loading"
                else:
                    place = "last unloading" if same[-1] is x else "other unloading"
                out.append((abs(x["target"]), 1000.0 * sign * (x["estimate"] - x["measured"]),
                            1000.0 * sign * (x["estimate"] - x["target"]),
                            max(abs(x["steady_pct"]), abs(x["estimation_pct"])) > TARGETS["force_pct"],
                            (path, x["side"], x["phase"]), place))
    return out


def rms(values):
    return math.sqrt(sum(v * v for v in values) / len(values)) if values else float("nan")


def main():
    dirs = sys.argv[1:]
    if not dirs:
        sys.exit("usage: python bench/bench_held_out_misses.py RUNS_DIR [RUNS_DIR ...]")
    steps = held_out_steps(dirs)
    if not steps:
        sys.exit("no held-out force steps under %s" % ", ".join(dirs))
    actuators = sum(len(glob.glob(os.path.join(d, "run-*", "results.json"))) for d in dirs)
    print("held-out force steps: %d on %d actuators" % (len(steps), actuators))
    print("| drawn force | steps | estimate - gauge, rms | estimate - target, rms | beyond %g %% |" % TARGETS["force_pct"])
    print("| --- | --- | --- | --- | --- |")
    for lo, hi in zip(BANDS_N, BANDS_N[1:]):
        band = [s for s in steps if lo <= s[0] < hi]
        if not band:
            continue
        missed = sum(s[3] for s in band)
        print("| %g-%g N | %d | %.0f mN | %.0f mN | %d (%.0f %%) |" % (
            lo, hi, len(band), rms([s[1] for s in band]), rms([s[2] for s in band]), missed, 100.0 * missed / len(band)))
    missed = sum(s[3] for s in steps)
    print("all: %d of %d steps beyond %g %% (%.1f %%); estimate - gauge %.0f mN rms, estimate - target %.0f mN rms"
          % (missed, len(steps), TARGETS["force_pct"], 100.0 * missed / len(steps), rms([s[1] for s in steps]),
             rms([s[2] for s in steps])))
    print()
    print("| place in its side's sequence | steps | estimate - gauge, mean | rms | beyond %g %% |" % TARGETS["force_pct"])
    print("| --- | --- | --- | --- | --- |")
    for place in ("first loading", "other loading", "other unloading", "last unloading"):
        at = [s for s in steps if s[5] == place]
        if at:
            print("| %s | %d | %+.0f mN | %.0f mN | %d |" % (place, len(at), sum(s[1] for s in at) / len(at),
                                                          rms([s[1] for s in at]), sum(s[3] for s in at)))
    groups = {}
    for s in steps:
        groups.setdefault(s[4], []).append(s[1])
    means = {g: sum(v) / len(v) for g, v in groups.items()}
    own = [e - means[g] for g, v in groups.items() for e in v]
    dof = len(own) - len(groups)
    print("estimate - gauge shared by the steps of one actuator, side and direction (%d groups): %.0f mN rms of "
          "the groups' means; each step's own: %.0f mN rms (about the groups' means, over %d degrees of freedom)"
          % (len(groups), rms(list(means.values())), math.sqrt(sum(e * e for e in own) / dof) if dof > 0 else float("nan"), dof))


if __name__ == "__main__":
    main()
