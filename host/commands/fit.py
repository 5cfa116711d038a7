"""`host fit`: fit one calibration curve to a sweep CSV, report it, optionally plot and save it."""

import json
import math
import time

from host.commands._options import ranged
from host.errors import DONE, UserError, check_output_file
from host.fitting.model_select import DEFAULT_BUDGET
from host.fitting.models import MODELS
from host.fitting.pot_fit import RMS_REFUSE, fit_sweep, poor_fit, refusals
from host.terminal import note, output, warn


def add_parser(subparsers):
    p = subparsers.add_parser(
        "fit",
        help="fit a potentiometer calibration curve to a sweep CSV (default: auto, the choice host calibrate makes; "
        "--model bcm --order 3 is the paper's BCM); --out writes it into a calibration file",
        description="Fit a calibration curve (default: auto, the cheapest curve the firmware evaluates "
        "that predicts held-out samples as well as the best, as host calibrate chooses; --model bcm --order 3 is the paper's "
        "BCM) to a sweep CSV with columns raw,reference[,direction]. Prints the fit statistics, the "
        "sweep's own noise floor and what hygiene removed; optionally draws the fit and writes it to "
        "the calibration file the firmware loads.",
    )
    p.add_argument("sweep", metavar="SWEEP.csv", help="sweep CSV (header with raw and reference; direction optional)")
    p.add_argument(
        "--model",
        default="auto",  # as host calibrate and host demo: a newcomer's first fit is the one a calibration makes
        choices=list(MODELS) + ["auto"],
        help="calibration model (default auto, as host calibrate: the cheapest firmware model within 0.5 %% of "
        "the lowest cross-validated error, within --budget); bcm is the paper's",
    )
    p.add_argument("--order", type=ranged(int, 1, 64),
                   help="with a named --model: degree or number of knots/points (default: bcm 3, pwl 5, pcm 10, ...)")
    p.add_argument("--bounds", choices=("data", "paper"), default=None,
                   help="with --model bcm: the search box, data (default: handles in the reference range +-10%%, "
                   "w0=1, weight ratios 1/60..60) or paper (handles in [0, 60], weights in [1, 60])")
    p.add_argument("--budget", type=ranged(int, 4, 4096), default=DEFAULT_BUDGET, help="auto: most numbers the chosen model may store (default %d, as host calibrate)" % DEFAULT_BUDGET)
    p.add_argument("--out", metavar="CALIB.json", help="write (or update) this pot's section of the calibration file")
    p.add_argument("--pot", choices=("pot1", "pot2"), default="pot1", help="which pot --out writes (default pot1)")
    p.add_argument("--pot-id", metavar="ID",
                   help="--out: identity of the physical pot, e.g. its serial (default: the one the file already "
                   "records for --pot, else none)")
    p.add_argument("--board", metavar="NAME", help="--out: identity of the board (default: keep the file's)")
    p.add_argument("--adc-bits", type=ranged(int, 1, 16), help="--out: the board's ADC bits (default: guessed from the raw range)")
    p.add_argument("--full-scale", type=ranged(float, 1e-09, 1000000000000.0), metavar="RAW",
                   help="the converter's full scale in raw units, e.g. 3.3 for volts: rows tied on a rail (0 or "
                   "this) are clipped, and the sweep must cover 25%% of it (default: known only for ADC codes)")
    p.add_argument("--plot", metavar="FIT.png", help="draw data, fit and residuals to this PNG")
    p.add_argument("--unit", default="mm", help="the reference unit, for reports and plots (default mm)")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of the summary")
    p.add_argument("--force", action="store_true",
                   help="--out: write even a curve that is not monotone or whose rms is over %d times the sweep's "
                   "noise floor, or whose integer form falls anywhere (refused by default: such a sweep's reference is rarely a "
                   "function of its reading, and a board refuses a falling curve at boot)" % RMS_REFUSE)
    p.set_defaults(func=run)


def report(result, sweep, floors, unit, reason=None):
    """The readable summary (list of lines)."""
    noise = floors["noise_floor"]
    lines = ["sweep: %s" % sweep.describe()]
    lines.append("model: %s order %d (%d parameters)%s" % (result.model, result.order, result.n_params,
                                                             "  [auto: %s]" % reason if reason else ""))
    lines.append("rms: %.4g %s   max |error|: %.4g %s" % (result.rms, unit, result.max_abs, unit))
    if noise:
        lines.append("noise floor: %.4g %s   rms / noise floor: %.2f" % (noise, unit, result.rms / noise))
        if floors["hysteresis"]:
            lines.append("hysteresis: +-%.4g %s, so one curve can reach at best %.4g %s (rms / that: %.2f)"
                         % (abs(floors["hysteresis"]), unit, floors["curve_floor"], unit,
                            result.rms / floors["curve_floor"]))
    else:
        lines.append("noise floor: unknown")
    lines.append("monotone: %s" % ("yes" if result.monotone else "NO (cannot be inverted)"))
    lines.append("fit time: %.1f ms" % (1000 * result.fit_seconds))
    lines.extend("note: %s" % n for n in result.notes)
    return lines


def run(args):
    from host.calibration.file import CalibrationFile, pot_section
    from host.fitting.sweep import adc_bits_of, load_sweep

    if args.model == "auto":  # auto chooses the model and its order: ignoring these would mislead
        given = [name for name, value in (("--order", args.order), ("--bounds", args.bounds)) if value is not None]
        if given:
            raise UserError("%s needs a named --model: auto chooses the model and its order (e.g. --model bcm %s)"
                            % (" and ".join(given), "--order 3" if args.order is not None else "--bounds paper"))
    say = (lambda msg: None) if args.json else note
    if args.out:
        check_output_file(args.out, "calibration file")  # before the fit, not after it
    sweep = load_sweep(args.sweep, full_scale=args.full_scale)
    t0 = time.perf_counter()
    result, floors, reason = fit_sweep(sweep, args.model, args.order, args.bounds or "data", args.budget, progress=say)
    noise = floors["noise_floor"]
    total = time.perf_counter() - t0
    out = result.summary()
    out.update(
        sweep=str(args.sweep),
        unit=args.unit,
        rms_over_noise=(result.rms / noise) if noise else None,
        **floors,
        n_input=sweep.n_input,
        exclusions=sweep.exclusions,
        total_seconds=total,
    )
    if reason:
        out["auto_reason"] = reason
    if args.plot:
        from host.fitting.plots import plot_fit

        say("drawing %s" % args.plot)
        try:
            plot_fit(args.plot, sweep.x, sweep.y, result, unit=args.unit, noise=noise, direction=sweep.direction)
        except OSError as exc:
            raise UserError("cannot write plot %s: %s" % (args.plot, exc)) from None
        out["plot"] = str(args.plot)
    if args.out:
        finite = [v for v in sweep.y if math.isfinite(v)]
        why = refusals(result, noise, (max(finite) - min(finite)) if finite else None)
        if why and not args.force:
            raise UserError("not writing %s: %s (--force writes it anyway)" % (args.out, "; ".join(why)))
        if poor_fit(result, noise):
            warn("rms %.4g is %.0f times the noise floor: a poor fit (%s)" % (
                result.rms, result.rms / noise, "a larger --budget allows a longer table" if args.model == "auto"
                else "try --model auto, the default"))
        bits = args.adc_bits or adc_bits_of(sweep.x)
        if bits is None:
            raise UserError("raw does not look like ADC codes; give --adc-bits to write a calibration file")
        say("writing %s section of %s (%d-bit ADC)" % (args.pot, args.out, bits))
        try:
            cal = CalibrationFile(args.out)
            section = pot_section(result, bits, pot_id=args.pot_id, rising=not args.force)
            backup = cal.keep_previous()  # never a lost calibration: the file as it was, beside it
            if backup is not None:
                say("kept the previous calibration as %s" % backup)
            crc = cal.set_sections({args.pot: section}, board=args.board)
            if cal.left_out:
                warn("%s left out of %s: measured with the old %s curve (kept in %s)"
                     % (", ".join(cal.left_out), args.out, args.pot, backup))
        except OSError as exc:
            raise UserError("cannot write calibration %s: %s" % (args.out, exc)) from None
        except (ValueError, OverflowError) as exc:  # no inf or NaN ever reaches a file
            raise UserError("cannot export this fit to %s: %s" % (args.out, exc)) from None
        out["calibration"] = {"path": str(args.out), "section": args.pot, "crc32": crc, "adc_bits": bits,
                              "board": args.board, "pot_id": args.pot_id}
    if args.json:
        output(json.dumps(out, indent=2, default=float))
        return DONE
    output("\n".join(report(result, sweep, floors, args.unit, reason)))
    if args.plot:
        output("plot: %s" % args.plot)
    if args.out:
        output("calibration: %s section %s written (crc32 %08x)" % (args.out, args.pot, crc))
    return DONE
