"""Wall time of `host compare` over orders 2-15 with every default model, on the example sweep.

    .venv/bin/python bench/bench_compare.py [SWEEP.csv] [--runs 1]

Runs the real CLI in a subprocess three times per run: as a user runs it (no OPENBLAS_NUM_THREADS
set, so host/cli.py pins it to 1: small least-squares problems are much faster single-threaded
when the CPUs are busy), with OPENBLAS_NUM_THREADS set to the CPU count (the CLI keeps a value
the user set, so this is the threaded BLAS it avoids), and with --jobs 2 worker processes (1 BLAS
thread each). Prints the per-model fit times the CLI reports and the total wall time ("fitting"
is the CLI's own figure, without start-up).
"""

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def run_once(sweep, env_extra, extra_args=()):
    env = dict(os.environ, **env_extra)
    if "OPENBLAS_NUM_THREADS" not in env_extra:
        env.pop("OPENBLAS_NUM_THREADS", None)  # what the CLI does on its own, not what our shell set
    with tempfile.TemporaryDirectory() as out:
        t0 = time.perf_counter()
        proc = subprocess.run([sys.executable, "-m", "host", "compare", str(sweep), "--orders", "2-15", "--out", out,
                               *extra_args],
                              capture_output=True, text=True, cwd=REPO, env=env)
        wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(proc.stderr)
    models = re.findall(r"\] (\S+)\s+(?:orders[ 0-9]*: )?\d+ fits in ([0-9.]+) s", proc.stderr)
    fits = re.search(r"(\d+) fits in ([0-9.]+) s", proc.stdout)
    return wall, float(fits.group(2)), models


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sweep", nargs="?", default=str(REPO / "examples" / "sweep_60mm.csv"))
    ap.add_argument("--runs", type=int, default=1)
    args = ap.parse_args(argv)
    print("host compare %s --orders 2-15 (models bcm,pcm,cheb,spline,lut,pwl); %d CPUs; load %s"
          % (Path(args.sweep).name, os.cpu_count(), " ".join("%.1f" % v for v in os.getloadavg())))
    threads = str(os.cpu_count() or 1)
    configs = (
        ("as run (CLI: 1 BLAS thread)", {}, ()),
        ("OPENBLAS_NUM_THREADS=" + threads, {"OPENBLAS_NUM_THREADS": threads}, ()),
        ("--jobs 2, 1 BLAS thread", {}, ("--jobs", "2")),
    )
    for label, extra, extra_args in configs:
        for _ in range(args.runs):
            wall, fitting, models = run_once(args.sweep, extra, extra_args)
            per_model = ", ".join("%s %.2f s" % (m, float(s)) for m, s in models)
            print("%-28s wall %.2f s (fitting %.2f s): %s" % (label, wall, fitting, per_model))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
