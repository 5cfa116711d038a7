"""Paper Fig. 7: displacement (D2) control to targets over the stroke, error by the reference.

The reference sensor is mounted on pot 2 (the output block); each target is held in position
mode until D2 settles, then the reference is averaged and the error is target - reference.
Run once with the nominal (2-point) pot calibration and once with the accepted one.

Where is 0 mm? The reference's own zero is wherever it was mounted, so it is zeroed the way a
person zeroes a dial gauge: against the block's end stops, the middle of the two being 30 mm
(`zero_at_stops`). The calibration measures positions from the same stops (pot 2's sweep), so
a target means the same place to the firmware and to the reference, whatever part of the
assembly error pot 2 carries.
"""

import numpy as np

from host.guided import acquire
from host.guided.prompts import end_progress, progress_line
from host.guided import stroke
from host.guided.rig import reference_mm

# The paper's targets run 1-60 mm; the firmware's soft stroke limits (0.5 and 59.5 mm) keep the
# block off the end stops, so the targets span the project's 1-59 mm: 1 mm inside each end and
# every 5 mm between, on any stroke (host/guided/stroke.py position_targets).
TARGETS_MM = stroke.position_targets(stroke.DEFAULT_MM)
# Settled: the 0.1 s mean of the firmware's D2 within SETTLE_UM of the target for 0.2 s (board
# time; host.guided.acquire.settle). The settle time is from the command to entering that band
# for good; the error is then the reference's 0.3 s mean against the target.
SETTLE_UM = 50


def zero_at_stops(session, rig, ref_scale, duty=2500, middle_mm=30.0):
    """The reference (on pot 2) zeroed against the block's end stops: {"low", "high": its readings
    there in mm, "shift": what to add to a reading so that the stops' middle reads `middle_mm`,
    the middle of the nominal stroke, as the calibration's frame has it}."""
    rig.mount_reference("pot2")
    bits = session.board["adc_bits"]
    read = {}
    with acquire.open_stroke(session.client):
        for end, sign in (("low", -1), ("high", 1)):
            rec = acquire.at_stop(acquire.drive_to_stop(session.client, sign * duty))
            read[end] = float(np.median(reference_mm(rec[:, acquire.COL["raw_ref"]], bits, ref_scale)))
    read["shift"] = middle_mm - (read["low"] + read["high"]) / 2.0
    return read


def run_targets(session, rig, ref_scale, zero, targets=TARGETS_MM, label=""):
    """Rows: target mm, reference mm (zeroed by `zero`, from zero_at_stops), error mm, D2 reported
    by the firmware, settled."""
    rig.mount_reference("pot2")
    client = session.client
    rows = []
    for t in targets:
        ok, rec, settle_s = acquire.hold(client, "position", int(t * 1000), "d2_um", SETTLE_UM, timeout_s=6.0, measure_s=0.3)
        ref = float(np.mean(reference_mm(rec[:, acquire.COL["raw_ref"]], session.board["adc_bits"], ref_scale))) + zero["shift"] if len(rec) else float("nan")
        d2 = acquire.mean(rec, "d2_um") / 1000.0
        rows.append({"target": float(t), "reference": ref, "error": t - ref, "d2": d2, "settled": bool(ok), "settle_s": settle_s})
        progress_line("  %s target %5.1f mm: reference %7.3f mm, error %+.3f mm%s" % (label, t, ref, t - ref, "" if ok else " (not settled)"))
    end_progress()
    client.call("stop")
    return rows


def max_error(rows, lo=float("-inf"), hi=float("inf")):
    errs = [abs(r["error"]) for r in rows if lo <= r["target"] <= hi and np.isfinite(r["error"])]
    return max(errs) if errs else float("nan")


def plot(path, before, after):
    from matplotlib.figure import Figure  # drawn and written without pyplot: no backend is chosen

    fig = Figure(figsize=(7.5, 4.5))
    ax = fig.subplots()
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
