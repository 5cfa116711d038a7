"""`host fit`: fit one calibration curve to a sweep CSV, report it, optionally plot and save it."""

import dataclasses
import importlib
import json
import math
import sys
import time

from host.errors import UserError
from host.models import MODELS
from host.numbers import ranged
from host.terminal import note

DEFAULT_ORDER = {"bcm": 3, "pcm": 10, "pcm-raw": 10, "cheb": 10, "spline": 8, "pchip": 8, "lut": 16, "pwl": 5}
MAX_ORDER = 40


def add_parser(subparsers):
    p = subparsers.add_parser(
        "fit",
        help="fit a potentiometer calibration curve to a sweep CSV",
        description="Fit a calibration curve (default: the paper's BCM of degree 3) to a sweep "
        "CSV with columns raw,reference[,direction]. Prints the fit statistics, the sweep's own "
        "noise floor and what hygiene removed; optionally draws the fit and writes it to the "
        "calibration file the firmware loads.",
    )
    p.add_argument("sweep", metavar="SWEEP.csv", help="sweep CSV (header with raw and reference; direction optional)")
    p.add_argument(
        "--model",
        default="bcm",
        choices=list(MODELS) + ["auto"],
        help="calibration model (default bcm); auto = the cheapest firmware model near the noise floor",
    )
    p.add_argument("--order", type=ranged(int, 1, 64), help="degree or number of knots/points (default: bcm 3, pwl 5, pcm 10, ...)")
    p.add_argument("--bounds", choices=("data", "paper"), default="data",
                   help="bcm search box: data (handles in the reference range +-10%%, w0=1, weight ratios 1/60..60) "
                   "or paper (handles in [0, 60], weights in [1, 60])")
    p.add_argument("--budget", type=ranged(int, 4, 4096), default=12, help="auto: most numbers the chosen model may store (default 12)")
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
                   "noise floor (refused by default: such a sweep's reference is rarely a function of its reading)" % RMS_REFUSE)
    p.set_defaults(func=run)


def _check_model_available(model):
    if model == "auto":
        return
    module = MODELS[model][0]
    try:
        importlib.import_module(module)
    except ImportError:
        raise UserError("model %r is not available in this build (module %s is missing)" % (model, module)) from None


def fit_sweep(sweep, model="bcm", order=None, bounds="data", budget=12, progress=None):
    """(FitResult, floors dict, auto reason or None) for a loaded Sweep.

    floors: noise_floor (the scatter, by direction), hysteresis (half the gap between directions)
    and curve_floor (what one curve of raw alone can reach: both combined), None when unknown.
    """
    from host.model_select import select_model
    from host.models import fit_model
    from host.noise_floor import estimate_hysteresis, estimate_noise

    _check_model_available(model)
    try:
        noise = estimate_noise(sweep.x, sweep.y, sweep.direction)
        hyst = estimate_hysteresis(sweep.x, sweep.y, sweep.direction)
        floors = {"noise_floor": noise, "hysteresis": hyst, "curve_floor": float((noise**2 + hyst**2) ** 0.5)}
    except ValueError:
        floors = {"noise_floor": None, "hysteresis": None, "curve_floor": None}
    if model == "auto":
        sel = select_model(sweep.x, sweep.y, floors["curve_floor"], budget=budget, n_excluded=sweep.n_excluded,
                           progress=progress)
        return sel.result, floors, sel.reason
    order = DEFAULT_ORDER[model] if order is None else order
    if not 1 <= order <= MAX_ORDER:
        raise UserError("--order must be between 1 and %d, not %d" % (MAX_ORDER, order))
    options = {"bounds": bounds} if model == "bcm" else {}
    if progress:
        progress("fitting %s order %d to %d samples" % (model, order, sweep.x.size))
    try:
        result = fit_model(model, sweep.x, sweep.y, order, n_excluded=sweep.n_excluded, **options)
    except ValueError as exc:
        raise UserError("%s order %d cannot be fitted to this sweep: %s" % (model, order, exc)) from None
    return result, floors, None


def adc_bits_of(sweep):
    from host.sweep import _full_scale

    fs = _full_scale(sweep.x)
    if fs is None:
        raise UserError("raw does not look like ADC codes; give --adc-bits to write a calibration file")
    return fs.bit_length()


def write_pot(path, pot, result, adc_bits, pot_id=None, board=None):
    """Write `result` as section `pot` of the calibration file (with the pot's and the board's
    identity when given); returns the file's CRC."""
    try:
        from host.calibration_file import pot_section, update_section
    except ImportError:
        raise UserError("calibration file support not available (host/calibration_file.py is missing)") from None
    from host.rational_bezier import elevate

    if result.model == "bcm" and result.order < 3:  # the firmware's bcm3 runs it after exact elevation
        coeffs = elevate(result.coefficients, 3)
        result = dataclasses.replace(result, order=3, coefficients=coeffs,
                                     notes=result.notes + ["degree %d elevated to 3 (same curve)" % result.order])
    update_section(path, pot, pot_section(result, adc_bits, pot_id=pot_id), board=board)
    from firmware.calibration import parse_document  # the CRC the board will check

    with open(path) as fh:
        return parse_document(fh.read())[1]


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


RMS_WARN = 10  # rms / noise floor: a poor fit (a quadratic on a knee-shaped pot is ~17)
RMS_REFUSE = 50  # ... and a sweep that is not a calibration (a reference that is not a function of the reading)
SPAN_REFUSE = 0.02  # rms over 2 % of the reference's span (1.2 mm on a 60 mm pot; BCM-3 leaves ~0.2 %)


def refusals(result, noise, span):
    """Why a fit must not be written as a calibration (empty when it may)."""
    why = []
    if not (math.isfinite(result.rms) and math.isfinite(result.max_abs)):
        why.append("its error is not finite (rms %s): the sweep's numbers are out of range" % result.rms)
    elif span and result.rms > SPAN_REFUSE * span:
        why.append("its rms %.4g is %.1f %% of the reference's span %.4g (limit %.0f %%): is the reference a function "
                   "of the reading?" % (result.rms, 100 * result.rms / span, span, 100 * SPAN_REFUSE))
    elif noise and result.rms > RMS_REFUSE * noise:
        why.append("its rms %.4g is %.0f times the sweep's noise floor %.4g (limit %d): is the reference a function "
                   "of the reading?" % (result.rms, result.rms / noise, noise, RMS_REFUSE))
    if not result.monotone:
        why.append("the curve is not monotone, so the firmware could not tell positions apart")
    elif float(result(result.x_range[1])) < float(result(result.x_range[0])):
        why.append("the position falls as the reading rises, and the firmware refuses such a curve (positions must "
                   "grow toward 60 mm): add this pot to \"pot_invert\" in the board file (host calibrate bringup "
                   "finds it) and sweep again")
    return why


def run(args):
    from host.sweep import load_sweep

    _check_model_available(args.model)
    say = (lambda msg: None) if args.json else note
    sweep = load_sweep(args.sweep, full_scale=args.full_scale)
    t0 = time.perf_counter()
    result, floors, reason = fit_sweep(sweep, args.model, args.order, args.bounds, args.budget, progress=say)
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
        from host.fit_plots import plot_fit

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
        if noise and RMS_WARN * noise < result.rms <= RMS_REFUSE * noise:
            say("warning: rms %.4g is %.0f times the noise floor: a poor fit (try --model auto)" % (result.rms, result.rms / noise))
        bits = args.adc_bits or adc_bits_of(sweep)
        say("writing %s section of %s (%d-bit ADC)" % (args.pot, args.out, bits))
        try:
            crc = write_pot(args.out, args.pot, result, bits, pot_id=args.pot_id, board=args.board)
        except OSError as exc:
            raise UserError("cannot write calibration %s: %s" % (args.out, exc)) from None
        except (ValueError, OverflowError) as exc:  # no inf or NaN ever reaches a file
            raise UserError("cannot export this fit to %s: %s" % (args.out, exc)) from None
        out["calibration"] = {"path": str(args.out), "section": args.pot, "crc32": crc, "adc_bits": bits,
                              "board": args.board, "pot_id": args.pot_id}
    if args.json:
        print(json.dumps(out, indent=2, default=float))
        return 0
    print("\n".join(report(result, sweep, floors, args.unit, reason)))
    if args.plot:
        print("plot: %s" % args.plot)
    if args.out:
        print("calibration: %s section %s written (crc32 %08x)" % (args.out, args.pot, crc))
    return 0
