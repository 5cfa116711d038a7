"""Calibration 1 (the paper's section 2): each pot's inherent nonlinearity against the reference sensor.

For each pot the rig mounts the reference in parallel with it; the actuator sweeps forward and
backward at a low open-loop duty while the firmware logs the pot's code and the reference's code
(`--reference adc`), or the person types dial-gauge readings at stops (`--reference manual`).
The sweep is checked (host/guided/checks.py), fitted (by default `auto`: the cheapest curve the
firmware evaluates, BCM-3 or a free-knot piecewise-linear table, within 0.5 % of the lowest
cross-validated error, within a budget of stored numbers; `--model bcm --order 3` is the paper's),
exported to fixed point and returned as the pot1/pot2 sections.
"""

import time

import numpy as np

from firmware.calibration import STROKE_SECTION, convert
from host.calibration.file import pot_section, stroke_section
from host.errors import UserError
from host.guided import acquire, checks, stroke
from host.guided.outcome import StepOutcome
from host.guided.rig import reference_mm

RAW = {"pot1": "raw1", "pot2": "raw2"}


def adc_sweep(session, rig, pot, duty, ref_scale, say):
    """(raw, reference mm, direction, stops): the sweep, and the records still at each end stop.

    The still records join the sweep: the pot and the reference are read together there too,
    and without them a curve's ends are extrapolations (0.1-0.2 mm off at the stops on the
    simulated pots, where the moving part of the sweep ends a few codes short of them)."""
    rig.mount_reference(pot)
    stops = {}
    records, direction = acquire.sweep(session.client, duty, say, stops=stops, hz=acquire.SWEEP_HZ)
    records = np.concatenate([records, stops["high"], stops["low"]])
    direction = np.concatenate([direction, np.ones(len(stops["high"])), -np.ones(len(stops["low"]))])
    raw = records[:, acquire.COL[RAW[pot]]].astype(float)
    ref = reference_mm(records[:, acquire.COL["raw_ref"]], session.board["adc_bits"], ref_scale)
    return raw, ref, direction, stops


def end_stops(stops, adc_bits, ref_scale):
    """(low, high) reference mm and the median pot-2 code at the block's two end stops, from
    the records standing still at each end of a pot's sweep (the reference is on that pot then;
    the frame and the stroke section use pot 2's, the checks each pot's own: sweep_limits)."""
    out = {}
    for end in ("low", "high"):
        rec = stops.get(end)
        if rec is None or len(rec) == 0:
            return None
        out[end] = (float(np.median(reference_mm(rec[:, acquire.COL["raw_ref"]], adc_bits, ref_scale))),
                    int(round(float(np.median(rec[:, acquire.COL["raw2"]])))))
    return out if out["high"][0] - out["low"][0] > 1.0 else None


def sweep_limits(limits, ends):
    """The limits one pot's sweep is checked against, and the check on its end stops (a list of
    none or one). With the stops measured (`ends`, end_stops of that pot's sweep), the sweep must
    cover SWEEP_FRACTION of their distance as the reference on that pot read it, not of the
    nominal stroke: a pot's mount error stretches or shrinks its scale (one drawn actuator's 40.5
    mm stroke read 36.0 mm on pot 2 and 43.2 on pot 1), and that distance must itself reach
    limits.min_stops_mm (a block that jams part-way)."""
    import dataclasses

    if ends is None:
        return limits, []
    span = ends["high"][0] - ends["low"][0]
    narrowed = dataclasses.replace(limits, min_range_mm=min(limits.min_range_mm, stroke.SWEEP_FRACTION * span))
    return narrowed, [checks.check_stops(span, limits)]


def stroke_from(ends, offset_mm, pot2_section):
    """The stroke section: where the block's end stops are in D2, by the firmware's own converter
    of the new pot 2 curve at the codes read there (what the board will compute at the stops)."""
    kind, k = pot2_section["kind"], pot2_section["fixed"]
    lo, hi = (convert(kind, ends[e][1], k) / 1000.0 for e in ("low", "high"))
    return stroke_section(lo, hi, {"reference_mm": [ends["low"][0], ends["high"][0]], "centre_shift_mm": offset_mm,
                                   "length_mm": hi - lo})


def manual_sweep(session, rig, pot, points, prompter, say, length_mm):
    """Stop at `points` places each way over a `length_mm` stroke (short open-loop pushes) and ask
    the dial gauge."""
    rig.mount_reference(pot)
    client = session.client
    raws, refs, dirs = [], [], []
    # the stroke limits open for each motion only: not while the person reads the gauge
    with acquire.open_stroke(client):
        acquire.drive_to_stop(client, -2500)
    for sign in (1, -1):
        for i in range(points):
            if i:
                with acquire.open_stroke(client):
                    pulse = acquire.collect_pulse(client, sign * 2000, length_mm / points / 25.0)
                if acquire.stalled_at_end(pulse):
                    break
            rec = acquire.collect(client, 0.3)
            raws.append(acquire.mean(rec, RAW[pot]))
            refs.append(prompter.number("Dial gauge reading at stop %d (%s), mm:" % (len(raws), "forward" if sign > 0 else "backward")))
            dirs.append(sign)
    return np.array(raws), np.array(refs), np.array(dirs, dtype=float)


def fit_pot(raw, ref, direction, adc_bits, model, order, budget=None):
    from host.fitting.pot_fit import fit_sweep
    from host.fitting.sweep import sweep_from_arrays

    sweep = sweep_from_arrays(raw, ref, direction, source="pot sweep")
    fit, floors, reason = fit_sweep(sweep, model=model, order=order, **({"budget": budget} if budget else {}))
    return sweep, fit, floors, reason


def calibrate_pots(session, rig, prompter, opts):
    """Both pots: sweep, check, fit. Returns a StepOutcome with sections pot1 and pot2."""
    from host.fitting.plots import plot_fit

    bits = session.board["adc_bits"]
    sections, lines, plots, data = {}, [], [], {}
    all_ok = True
    swept = {}
    for pot in ("pot1", "pot2"):
        prompter.say("[pots] %s: reference sensor on %s" % (pot, pot))
        t0 = time.monotonic()
        if opts.reference == "manual":
            swept[pot] = manual_sweep(session, rig, pot, opts.manual_points, prompter, prompter.say,
                                      stroke.length(opts.stroke or stroke.DEFAULT_MM)) + ({},)
        else:
            swept[pot] = adc_sweep(session, rig, pot, opts.duty, opts.ref_scale, prompter.say)
        prompter.say("  %d samples in %.1f s" % (len(swept[pot][0]), time.monotonic() - t0))
    # The block's frame: the reference's own zero is wherever it was mounted, so positions are
    # measured from the block's end stops instead, as pot 2's sweep found them with the
    # reference on it: the middle of the two stops is the middle of the nominal stroke, 30 mm of
    # 0-60 (mounting error on pot 2 moves and stretches its scale, so the stops need not sit at
    # its ends in the reference's readings). Both pots take the same shift, so D1 and D2 stay in
    # one frame.
    ends = end_stops(swept["pot2"][3], bits, opts.ref_scale)
    offset = 0.0
    centre = stroke.middle(opts.stroke or stroke.DEFAULT_MM)
    if ends is not None:
        offset = (ends["low"][0] + ends["high"][0]) / 2.0 - centre
        lines.append("end stops: the reference read %.3f and %.3f mm at the block's end stops (stroke %.3f mm); "
                     "positions are shifted by %+.3f mm so that the middle of the stroke is %g mm"
                     % (ends["low"][0], ends["high"][0], ends["high"][0] - ends["low"][0], -offset, centre))
    else:
        lines.append("end stops: not measured (%s): positions stay in the reference's own frame and the soft "
                     "stroke limits are the stroke_min_um/stroke_max_um parameters alone"
                     % ("manual reference" if opts.reference == "manual" else "pot 2's sweep did not stall at both ends"))
    for pot in ("pot1", "pot2"):
        raw, ref, direction, stops = swept[pot]
        ref = ref - offset
        limits, stops_check = sweep_limits(opts.limits, end_stops(stops, bits, opts.ref_scale))
        found, noise, hyst = checks.check_sweep(raw, ref, direction, bits, limits)
        found += stops_check
        status = session.client.call("status")
        if status.get("faults"):  # e.g. a wiper that lifted: the firmware stopped the motor
            found.append(checks.Check("faults", False, float(len(status["faults"])), 0, "firmware faults",
                                      "the firmware stopped the motor: %s; fix the wiring, then run again" % status.get("last_fault")))
        lines += ["%s check %s" % (pot, c.line()) for c in found]
        ok = all(c.ok for c in found)
        all_ok &= ok
        if not ok:
            for c in found:
                prompter.say("  " + c.line())
            if len(raw) < 20:
                continue
        sweep, fit, floors, reason = fit_pot(raw, ref, direction, bits, opts.model, opts.order, opts.budget)
        png = opts.plot_path(pot)
        plot_fit(png, sweep.x, sweep.y, fit, noise=floors.get("noise_floor"), direction=sweep.direction,
                 title="%s: %s order %d, rms %.1f um, max %.1f um" % (pot, fit.model, fit.order, 1000 * fit.rms, 1000 * fit.max_abs))
        plots.append(png)
        try:
            sections[pot] = pot_section(fit, bits, pot_id=pot)
        except UserError as exc:
            all_ok = False
            lines.append("%s: %s" % (pot, exc))
            continue
        fixed = sections[pot]["fixed_check"]
        lines.append("%s fit: %s order %d, rms %.1f um, max %.1f um, noise floor %.1f um, hysteresis %.1f um, "
                     "monotone %s, fixed-point error %.2f um%s" % (
                         pot, fit.model, fit.order, 1000 * fit.rms, 1000 * fit.max_abs, 1000 * noise, 1000 * hyst,
                         "yes" if fit.monotone else "NO", fixed["max_error"], "; " + reason if reason else ""))
        data[pot] = {"raw": sweep.x, "ref": sweep.y, "direction": sweep.direction, "fit": fit, "noise": noise}
    if ends is not None and "pot2" in sections:
        try:
            sections[STROKE_SECTION] = stroke_from(ends, offset, sections["pot2"])
            lo, hi = sections[STROKE_SECTION]["end_stops_mm"]
            lines.append("end stops in D2: %.3f and %.3f mm (the firmware keeps its soft limits stop_margin_um inside)"
                         % (lo, hi))
        except UserError as exc:
            lines.append("end stops: %s" % exc)
    data["end_stops"] = None if ends is None else {"reference_mm": [ends["low"][0], ends["high"][0]], "shift_mm": -offset}
    return StepOutcome("pots", sections, lines, plots, ok=all_ok and "pot1" in sections and "pot2" in sections, data=data)
