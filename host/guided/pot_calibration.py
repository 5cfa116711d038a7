"""Calibration 1 (the paper's section 2): each pot's inherent nonlinearity against the reference sensor.

For each pot the rig mounts the reference in parallel with it; the actuator sweeps forward and
backward at a low open-loop duty while the firmware logs the pot's code and the reference's code
(`--reference adc`), or the person types dial-gauge readings at stops (`--reference manual`).
The sweep is checked (host/guided/checks.py), fitted (by default `auto`: the cheapest curve the
firmware evaluates, BCM-3 or a free-knot piecewise-linear table, that gets within 10 % of the
sweep's noise floor, within a budget of stored numbers; `--model bcm --order 3` is the paper's),
exported to fixed point and returned as the pot1/pot2 sections.
"""

import time

import numpy as np

from host.calibration_file import pot_section
from host.errors import UserError
from host.guided import acquire, checks
from host.guided.outcome import StepOutcome
from host.guided.rig import reference_mm

RAW = {"pot1": "raw1", "pot2": "raw2"}


def adc_sweep(session, rig, pot, duty, ref_scale, say):
    rig.mount_reference(pot)
    records, direction = acquire.sweep(session.client, duty, say)
    raw = records[:, acquire.COL[RAW[pot]]].astype(float)
    ref = reference_mm(records[:, acquire.COL["raw_ref"]], session.board["adc_bits"], ref_scale)
    return raw, ref, direction


def manual_sweep(session, rig, pot, points, prompter, say):
    """Stop at `points` places each way (short open-loop pushes) and ask the dial gauge."""
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
                    pulse = acquire.collect_pulse(client, sign * 2000, 60.0 / points / 25.0)
                if acquire.stalled_at_end(pulse):
                    break
            rec = acquire.collect(client, 0.3)
            raws.append(acquire.mean(rec, RAW[pot]))
            refs.append(prompter.number("Dial gauge reading at stop %d (%s), mm:" % (len(raws), "forward" if sign > 0 else "backward")))
            dirs.append(sign)
    return np.array(raws), np.array(refs), np.array(dirs, dtype=float)


def fit_pot(raw, ref, direction, adc_bits, model, order, budget=None):
    from host.commands.fit import fit_sweep
    from host.sweep import sweep_from_arrays

    sweep = sweep_from_arrays(raw, ref, direction, source="pot sweep")
    fit, floors, reason = fit_sweep(sweep, model=model, order=order, **({"budget": budget} if budget else {}))
    return sweep, fit, floors, reason


def calibrate_pots(session, rig, prompter, opts):
    """Both pots: sweep, check, fit. Returns a StepOutcome with sections pot1 and pot2."""
    from host.fit_plots import plot_fit

    bits = session.board["adc_bits"]
    sections, lines, plots, data = {}, [], [], {}
    all_ok = True
    for pot in ("pot1", "pot2"):
        prompter.say("[pots] %s: reference sensor on %s" % (pot, pot))
        t0 = time.monotonic()
        if opts.reference == "manual":
            raw, ref, direction = manual_sweep(session, rig, pot, opts.manual_points, prompter, prompter.say)
        else:
            raw, ref, direction = adc_sweep(session, rig, pot, opts.duty, opts.ref_scale, prompter.say)
        prompter.say("  %d samples in %.1f s" % (len(raw), time.monotonic() - t0))
        found, noise, hyst = checks.check_sweep(raw, ref, direction, bits, opts.limits)
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
        png = opts.out_dir / ("calibration-%s.png" % pot)
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
    return StepOutcome("pots", sections, lines, plots, ok=all_ok and len(sections) == 2, data=data)
