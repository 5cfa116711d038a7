"""Paper Fig. 3a from the run's own pot sweep: objective vs order for BCM, PCM and PWL.

Uses host.fitting.compare (the same fits and scores as `host compare`) on the sweep the guided pot
calibration logged, and writes fig3a.png/.md/.csv into the report directory.
"""

from host.fitting.compare import compare_models, write_outputs

ORDERS = list(range(2, 13))
MODELS = ("bcm", "pcm", "pwl")


def run(sweep_x, sweep_y, noise, out_dir, pot, say=print, orders=ORDERS, models=MODELS):
    from host.terminal import end_progress, progress_line

    def fitting(name, order):  # a model's orders take up to a minute together: say where it is
        progress_line("  fig. 3a: fitting %s at order %d of %d-%d" % (name, order, orders[0], orders[-1]), every=5.0)

    def progress(name, i, n, seconds):
        end_progress()
        say("  fig. 3a: %s fitted at %d orders in %.1f s (%d/%d)" % (name, len(orders), seconds, i, n))

    rows = compare_models(sweep_x, sweep_y, orders, models=models, noise=noise, progress=progress, on_order=fitting)
    paths = write_outputs(rows, out_dir, "fig3a", "Objective vs order, %s sweep of this run" % pot, len(sweep_x), noise)
    return rows, paths


def norm_at(rows, model, order):
    for r in rows:
        if r["model"] == model and r["order"] == order:
            return r["norm2"]
    return float("nan")


def pcm_order_matching(rows, norm):
    """Lowest PCM order whose objective is at or below `norm` (None if none in the table)."""
    hits = [r["order"] for r in rows if r["model"] == "pcm" and r["norm2"] <= norm]
    return min(hits) if hits else None
