"""Paper Fig. 7: displacement (D2) control to targets over the stroke, error by the reference.

The reference sensor is mounted on pot 2 (the output block); each target is held in position
mode until D2 settles, then the reference is averaged and the error is target - reference.
Run once with the nominal (2-point) pot calibration and once with the accepted one.
"""

import numpy as np

from host.guided import acquire
from host.guided.prompts import end_progress, progress_line
from host.guided.rig import reference_mm

# The paper's targets run 1-60 mm; the firmware's soft stroke limits (0.5 and 59.5 mm) keep the
# block off the end stops, so the targets span the project's 1-59 mm.
TARGETS_MM = (1, 5, 10, 15, 20, 25, 30, 35, 40, 45, 50, 55, 59)


def run_targets(session, rig, ref_scale, targets=TARGETS_MM, label=""):
    """Rows: target mm, reference mm, error mm, D2 reported by the firmware, settled."""
    rig.mount_reference("pot2")
    client = session.client
    rows = []
    for t in targets:
        ok, rec = acquire.hold(client, "position", int(t * 1000), "d2_um", 50, timeout_s=6.0, measure_s=0.3)
        ref = float(np.mean(reference_mm(rec[:, acquire.COL["raw_ref"]], session.board["adc_bits"], ref_scale))) if len(rec) else float("nan")
        d2 = acquire.mean(rec, "d2_um") / 1000.0
        rows.append({"target": float(t), "reference": ref, "error": t - ref, "d2": d2, "settled": bool(ok)})
        progress_line("  %s target %5.1f mm: reference %7.3f mm, error %+.3f mm%s" % (label, t, ref, t - ref, "" if ok else " (not settled)"))
    end_progress()
    client.call("stop")
    return rows


def max_error(rows, lo=1.0, hi=59.0):
    errs = [abs(r["error"]) for r in rows if lo <= r["target"] <= hi and np.isfinite(r["error"])]
    return max(errs) if errs else float("nan")


def plot(path, before, after):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 4.5))
    for rows, name, style in ((before, "nominal 2-point pot calibration", "o-"), (after, "after calibration", "s-")):
        ax.plot([r["target"] for r in rows], [r["error"] for r in rows], style, ms=4,
                label="%s (max |e| %.3f mm)" % (name, max_error(rows)))
    ax.axhline(0, color="0.5", lw=0.6)
    ax.set_xlabel("target D2 (mm)")
    ax.set_ylabel("error = target - reference (mm)")
    ax.set_title("Displacement control (paper Fig. 7)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
