"""`host calibrate`: the guided calibration (pots, assembly Df, force) against a board or `sim`."""

from pathlib import Path

from host.errors import UserError
from host.guided.flow import STEPS, Options, run_steps


def add_parser(subparsers):
    p = subparsers.add_parser(
        "calibrate",
        help="guided calibration: pots, assembly (Df) and force, written to the calibration file and flashed",
        description="Guided calibration on the bench (SPEC sections 2-4). Each step says what to mount "
        "and waits for Enter, sweeps or loads the actuator with progress lines, checks the data, shows "
        "the fit statistics and a plot, and asks to accept (y), reject (n) or abort (a). Accepted "
        "sections are written atomically to the calibration file and flashed; the firmware must then "
        "report the file's CRC. With --port sim the rig is simulated (boards/sim/bench_rig.py).",
    )
    p.add_argument("step", nargs="?", choices=STEPS + ("all",), default="all", help="one step, or all in order (default)")
    p.add_argument("--port", required=True, help="serial port of the board (e.g. /dev/ttyACM0) or 'sim'")
    p.add_argument("--board", default=None, help="board name or file (default: what the firmware reports; sim: boards/sim.json)")
    p.add_argument("--yes", action="store_true", help="no questions: mount automatically (virtual rig), accept results that pass every check")
    p.add_argument("--out", default="calibration.json", metavar="FILE", help="calibration file to write (default calibration.json)")
    p.add_argument("--plots", default=None, metavar="DIR", help="where to write the PNG plots (default: beside --out)")
    p.add_argument("--reference", choices=("adc", "manual"), default="adc",
                   help="pots: the reference sensor on the board's reference ADC input (adc), or dial-gauge readings typed in (manual)")
    p.add_argument("--ref-zero-mm", type=float, default=None, help="reference sensor: position at code 0, mm (real boards)")
    p.add_argument("--ref-span-mm", type=float, default=None, help="reference sensor: travel over its full scale, mm (real boards)")
    p.add_argument("--manual-points", type=int, default=12, help="--reference manual: stops per direction (default 12)")
    p.add_argument("--model", default="bcm", help="pot model: bcm (default), pwl, auto, ... (see host fit --help)")
    p.add_argument("--order", type=int, default=None, help="pot model order (default: bcm 3, pwl 5)")
    p.add_argument("--duty", type=int, default=1500, help="open-loop duty of the sweeps, of 10000 (default 1500: ~13 mm/s)")
    p.add_argument("--df-order", default="4", help="Df polynomial order, or auto (cross-validation); default 4")
    p.add_argument("--force-order", default="2", help="F0(d) and d(F0) order, or auto; default 2 (quadratics)")
    p.add_argument("--rounds", type=int, default=2, help="force: loading/unloading rounds (paper: 5; default 2)")
    p.add_argument("--levels", type=int, default=8, help="force: duty steps per loading (default 8)")
    p.add_argument("--max-duty", type=int, default=5000, help="force: largest open-loop duty (default 5000: ~17 N)")
    p.add_argument("--anchor-mm", type=float, default=45.0, help="force: where the fibre goes taut, mm (default 45)")
    p.add_argument("--no-flash", action="store_true", help="write the file but do not flash it")
    p.set_defaults(func=run)


def options_from(args):
    out = Path(args.out)
    plots = Path(args.plots) if args.plots else (out.parent if str(out.parent) else Path("."))
    plots.mkdir(parents=True, exist_ok=True)

    def order(text, name):
        if text == "auto":
            return "auto"
        try:
            value = int(text)
        except ValueError:
            raise UserError("%s must be an integer or auto, not %r" % (name, text)) from None
        if not 1 <= value <= 8:
            raise UserError("%s must be 1..8" % name)
        return value

    if not 100 <= args.duty <= 6000:
        raise UserError("--duty must be within 100..6000")
    return Options(out=out, out_dir=plots, reference=args.reference, manual_points=args.manual_points,
                   model=args.model, order=args.order, duty=args.duty, df_order=order(args.df_order, "--df-order"),
                   force_order=order(args.force_order, "--force-order"), anchor_mm=args.anchor_mm, rounds=max(1, args.rounds),
                   levels=max(3, args.levels), max_duty=args.max_duty, flash=not args.no_flash)


def calibrate(args, say=print, ask=None):
    """Run the requested steps; returns {step: StepOutcome} (used by host experiment too)."""
    from host.guided.prompts import Prompter
    from host.guided.rig import Rig, reference_scale
    from host.guided.session import Session

    opts = options_from(args)
    steps = STEPS if args.step == "all" else (args.step,)
    prompter = Prompter(yes=args.yes, ask=ask, out=say)
    with Session(args.port, args.board, opts.out, say=say) as session:
        if args.yes and session.virtual is None and opts.reference == "manual":
            raise UserError("--yes with --reference manual: nobody to read the dial gauge")
        if "pots" in steps and opts.reference == "adc":
            opts.ref_scale = reference_scale(session.board, args.ref_zero_mm, args.ref_span_mm)
        rig = Rig(prompter, session.root)
        return run_steps(session, rig, prompter, steps, opts)


def run(args):
    accepted = calibrate(args)
    print("calibration %s: %s accepted" % (args.out, ", ".join(accepted) or "nothing"))
    return 0 if accepted else 1
