"""How far the fast BCM fit (a few local starts) is from a slow global search, degrees 2..6.

    .venv/bin/python bench/global_search_gap.py [--degrees 2-6] [--max-samples 4000]

Data: the example sweep and every real curve in ../shared/realdata (never copied here). For each
curve and degree: RMS of `fit_bcm` (the fast default) and of `fit_bcm_global` (differential
evolution over the log-weights, then a local polish), and the gap 100 * (fast - global) / global
in %. Target: within 1 %. A negative gap means the fast fit found the better optimum. Curves
longer than --max-samples are thinned to every k-th sample (both fits see the same data).
"""

import argparse
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent

from host.fitting.compare import parse_orders
from host.fitting.fit_result import residual_stats
from host.fitting.rational_bezier import fit_bcm, fit_bcm_global
from host.fitting.sweep import load_sweep

REALDATA = REPO.parent / "shared" / "realdata"


def curves(max_samples):
    paths = [REPO / "examples" / "sweep_60mm.csv"] + sorted(REALDATA.glob("*.csv"))
    for path in paths:
        sweep = load_sweep(path)
        step = max(1, int(np.ceil(len(sweep.x) / max_samples)))
        yield path.name, sweep.x[::step], sweep.y[::step], step


def rms_of(fit_fn, x, y, degree):
    t0 = time.perf_counter()
    fit = fit_fn(x, y, degree)
    seconds = time.perf_counter() - t0
    residual_stats(fit, x, y)
    return fit.rms, seconds


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--degrees", default="2-6")
    ap.add_argument("--max-samples", type=int, default=4000)
    args = ap.parse_args(argv)
    degrees = parse_orders(args.degrees)
    print("| curve | samples | degree | fast rms | global rms | gap % | fast s | global s |")
    print("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    gaps = []
    for name, x, y, step in curves(args.max_samples):
        label = "%d (every %d)" % (len(x), step) if step > 1 else "%d" % len(x)
        for degree in degrees:
            fast, t_fast = rms_of(fit_bcm, x, y, degree)
            best, t_global = rms_of(fit_bcm_global, x, y, degree)
            gap = 100.0 * (fast - best) / best
            gaps.append(gap)
            print("| %s | %s | %d | %.5g | %.5g | %+.2f | %.2f | %.1f |"
                  % (name, label, degree, fast, best, gap, t_fast, t_global), flush=True)
    gaps = np.array(gaps)
    print("\nworst gap %+.2f %%, median %+.2f %%; %d of %d cases within 1 %%"
          % (gaps.max(), np.median(gaps), int(np.sum(gaps <= 1.0)), gaps.size))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
