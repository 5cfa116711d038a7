"""The held-out Df again: the paper experiment's validation sweep repeated on one actuator of a
robustness run, with that run's own calibration, to see how much the figure moves from one sweep
to the next (lsea-kit issue 26, item 4: block friction deflecting a soft spring).

    .venv/bin/python bench/bench_df_validation.py --runs DIR [--duty 1200] [--repeat 3] SEED

DIR is what `bench/bench_robustness.py --out DIR` wrote: DIR/board-SEED.json (the simulated
actuator) and DIR/run-SEED/calibration.json. Each repeat starts the virtual board with both, sweeps
at no load (host.guided.acquire.sweep, as host/experiments/held_out.py df_validation does) and
prints the held-out Df (each direction's 1 mm bin means averaged, the peak), the pooled peak and
the friction's deflection, then the bins whose direction-balanced mean passes 0.04 mm. Simulated
actuator, real firmware on the MicroPython unix port; about a minute a repeat.
"""

import argparse
import os
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)


def sweep_once(board, calibration, duty):
    from host.guided import acquire
    from host.guided.prompts import Prompter
    from host.guided.rig import Rig
    from host.guided.session import Session

    with Session("sim", board, calibration, say=lambda text: None) as session:
        rig = Rig(Prompter(yes=True, out=lambda text: None), session.virtual, adc_bits=session.board["adc_bits"])
        rig.no_load()
        return acquire.sweep(session.client, duty)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("seed")
    ap.add_argument("--runs", required=True, help="a robustness run's output directory")
    ap.add_argument("--duty", type=int, default=1200, help="the sweep's duty (the paper experiment's: 0.8 x 1500)")
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args()
    from host.experiments.held_out import direction_balanced_peak
    from host.fitting.assembly import STOP_ZONE_UM, near_the_stops
    from host.guided.acquire import COL

    board = os.path.join(a.runs, "board-%s.json" % a.seed)
    calibration = os.path.join(a.runs, "run-%s" % a.seed, "calibration.json")
    for path in (board, calibration):
        if not os.path.exists(path):
            sys.exit("not found: %s" % path)
    for k in range(a.repeat):
        records, direction = sweep_once(board, calibration, a.duty)
        d1, d2 = records[:, COL["d1_um"]].astype(float), records[:, COL["d2_um"]].astype(float)
        keep = ~near_the_stops(d2, STOP_ZONE_UM)
        x, resid, direction = d1[keep] / 1000.0, (d1 - d2)[keep] / 1000.0, direction[keep]
        peak, pooled, deflection = direction_balanced_peak(x, resid, direction)
        print("seed %s sweep %d (duty %d, %d samples): held-out Df %.3f mm, pooled %.3f mm, friction deflection %+.3f mm"
              % (a.seed, k + 1, a.duty, len(x), peak, pooled, deflection), flush=True)
        idx = np.floor(x - x.min()).astype(int)
        for b in range(idx.max() + 1):
            fwd, back = (idx == b) & (direction == 1), (idx == b) & (direction == -1)
            if fwd.sum() >= 3 and back.sum() >= 3:
                mean = (resid[fwd].mean() + resid[back].mean()) / 2.0
                if abs(mean) > 0.04:
                    print("    bin at %5.1f mm: forward %+.3f, backward %+.3f, balanced %+.3f mm"
                          % (x.min() + b + 0.5, resid[fwd].mean(), resid[back].mean(), mean))


if __name__ == "__main__":
    main()
