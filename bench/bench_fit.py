"""Fit speed: BCM degree 3 on a 2,000-sample simulated knee sweep (median over repeats).

    .venv/bin/python bench/bench_fit.py [--repeats 20] [--order 3]

Also times every baseline at the same order for context. Prints the BLAS thread setting:
on a busy 2-core machine OpenBLAS threads make small least-squares calls 50-100x slower, so
compare OPENBLAS_NUM_THREADS=1 against the default.
"""

import argparse
import os
import statistics
import time

from host.fitting.example_sweep import simulate_sweep
from host.fitting.models import fit_model
from host.fitting.sweep import sweep_from_arrays

BASELINES = ("pcm", "pcm-raw", "cheb", "spline", "pchip", "lut", "pwl")


def time_fit(name, x, y, order, repeats):
    times, fit = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        fit = fit_model(name, x, y, order)
        times.append(time.perf_counter() - t0)
    return times, fit


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=20)
    ap.add_argument("--order", type=int, default=3)
    args = ap.parse_args(argv)
    _, raw, ref, direction = simulate_sweep(per_direction=1000)
    sweep = sweep_from_arrays(raw, ref, direction)
    x, y = sweep.x, sweep.y
    print("sweep: %d simulated samples, %d after hygiene; OPENBLAS_NUM_THREADS=%s; %d CPUs"
          % (len(raw), len(x), os.environ.get("OPENBLAS_NUM_THREADS", "(default)"), os.cpu_count()))
    fit_model("bcm", x, y, args.order)  # warm-up: imports and caches
    times, fit = time_fit("bcm", x, y, args.order, args.repeats)
    print("bcm-%d: median %.1f ms, min %.1f ms, max %.1f ms over %d repeats; rms %.4f mm"
          % (args.order, 1e3 * statistics.median(times), 1e3 * min(times), 1e3 * max(times), args.repeats, fit.rms))
    for name in BASELINES:
        fit_model(name, x, y, args.order)
        times, fit = time_fit(name, x, y, args.order, max(3, args.repeats // 4))
        print("  %-7s order %d: median %8.2f ms; rms %.4f mm" % (name, args.order, 1e3 * statistics.median(times), fit.rms))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
