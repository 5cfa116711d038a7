"""`host compare`: objective vs order for every calibration model on one sweep (paper Fig. 3a)."""

import time
from pathlib import Path

from host.commands._options import parsed, ranged
from host.errors import DONE, UserError
from host.terminal import end_progress, live, note, output, warn
from host.fitting.compare import DEFAULT_MODELS, compare_models, parse_models, parse_orders, pivot_markdown, write_outputs


def add_parser(subparsers):
    p = subparsers.add_parser(
        "compare",
        help="compare calibration models over a range of orders (the paper's Fig. 3a)",
        description="Fit every model at every order to one sweep and report the residual 2-norm "
        "(the paper's objective), the RMS and the RMS relative to the sweep's noise floor, as a "
        "PNG plot (log scale, noise floor drawn) and a table (Markdown + CSV, also printed).",
    )
    p.add_argument("sweep", metavar="SWEEP.csv", help="sweep CSV with columns raw,reference[,direction]")
    p.add_argument("--orders", type=parsed(parse_orders, "orders"), default="2-15", help="orders to fit, e.g. 2-15 or 2,3,5 (default 2-15)")
    p.add_argument(
        "--models",
        type=parsed(parse_models, "models"),
        default=",".join(DEFAULT_MODELS),
        help="comma-separated models, or 'all' (default %s)" % ",".join(DEFAULT_MODELS),
    )
    p.add_argument("--out", metavar="DIR", default="compare_out", help="output directory (default compare_out)")
    p.add_argument(
        "--jobs",
        type=ranged(int, 1, 64),
        default=1,
        help="worker processes (default 1; more helps only when CPUs are idle: each worker "
        "re-imports numpy/scipy, about 1 s)",
    )
    p.set_defaults(func=run)


def time_left(elapsed_s, done, total):
    """", about N s left" after `done` of `total` models, from the wall time per fit so far (every
    model fits the same orders, so per model is per fit); "" once nothing is left. An estimate:
    the BCM at high order is slower than the rest, so it changes as models finish."""
    if done >= total or done <= 0:
        return ""
    left = elapsed_s / done * (total - done)
    return ", about %s left" % ("%.1f s" % left if left < 10 else "%.0f s" % left if left < 120 else "%.0f min" % (left / 60))


def run(args):
    from host.fitting.noise_floor import estimate_noise
    from host.fitting.sweep import load_sweep

    orders, models = args.orders, args.models
    sweep = load_sweep(args.sweep)
    try:
        noise = estimate_noise(sweep.x, sweep.y, sweep.direction)
    except ValueError:
        noise = None
    note("%s: %s; noise floor %s" % (args.sweep, sweep.describe(), "%.4g" % noise if noise else "unknown"))
    t0 = time.perf_counter()
    shown = {}

    def on_order(name, order):
        # a long sweep can keep one model busy for a minute: on a terminal, each order as it starts
        shown[name] = shown.get(name, "[%d/%d] %-7s orders" % (models.index(name) + 1, len(models), name)) + " %d" % order
        live(shown[name])

    def progress(name, i, n, seconds):
        left = time_left(time.perf_counter() - t0, i, n)  # wall time: with --jobs the fits overlap
        end_progress()
        note("[%d/%d] %-7s %d fits in %.2f s%s" % (i, n, name, len(orders), seconds, left))

    rows = compare_models(sweep.x, sweep.y, orders, models, noise=noise, progress=progress,
                          on_order=on_order if args.jobs == 1 else None, jobs=args.jobs)
    wall = time.perf_counter() - t0
    stem = Path(args.sweep).stem
    try:
        paths = write_outputs(rows, args.out, stem, "%s: model comparison" % stem, len(sweep.x), noise)
    except OSError as exc:
        raise UserError("cannot write to %s: %s" % (args.out, exc)) from None
    output("Objective (residual 2-norm) by order:\n")
    output(pivot_markdown(rows, "norm2"))
    if noise:
        output("\nRMS / noise floor (%.4g):\n" % noise)
        output(pivot_markdown(rows, "rms_over_noise", 3))
    failed = [r for r in rows if r["error"]]
    for r in failed:
        warn("%s order %d not fitted: %s" % (r["model"], r["order"], r["error"]))
    output("\n%d fits in %.2f s; wrote %s" % (len(rows), wall, ", ".join(str(p) for p in paths)))
    return DONE
