"""`host calibrate`: the guided calibration (pots, assembly Df, force) against a board or `sim`."""

from pathlib import Path

from firmware.board_config import STROKE_LIMIT_MM
from host.commands._options import PORT_HELP, add_uf2_argument, order_or_auto, ranged
from host.errors import DONE, MISSED, UserError
from host.fitting.models import MODELS
from host.guided.flow import BRINGUP, Options, STEPS, StepRefused, bringup_done, run_steps
from host.guided.gain_sweep import WEIGHT_FRACTION
from host.terminal import error, output

DEFAULT = Options()  # the defaults of the options below are Options' own: one place for each


def add_parser(subparsers):
    p = subparsers.add_parser(
        "calibrate",
        help="guided calibration: pots, assembly (Df), gain (the deformation along the stroke) and force, written to the calibration file and flashed",
        description="Guided calibration on the bench (the paper's sections 2-4). Each step says what to mount "
        "and waits for Enter, sweeps or loads the actuator with progress lines, checks the data, shows "
        "the fit statistics and a plot, and asks to accept (y), reject (n) or abort (a). Accepted "
        "sections are written atomically to the calibration file and flashed; the firmware must then "
        "report the file's CRC. With --port sim the rig is simulated (boards/sim/bench_rig.py).",
    )
    p.add_argument("step", nargs="?", choices=(BRINGUP,) + STEPS + ("all",), default="all",
                   help="one step, or all in order (default; bringup first unless it passed before on this board): "
                   "pots, assembly (Df), gain (a weight hung from the block, swept along the stroke: the deformation's "
                   "gain along it, so F0 holds away from the gauge's anchor), force")
    add_guided_arguments(p, yes_help="no questions: mount automatically (virtual rig), accept results that pass every check")
    p.add_argument("--out", default=str(DEFAULT.out), metavar="FILE", help="calibration file to write (default %(default)s)")
    p.add_argument("--plots", default=None, metavar="DIR", help="where to write the PNG plots (default: beside --out)")
    p.add_argument("--reference", choices=("adc", "manual"), default=DEFAULT.reference,
                   help="pots: the reference sensor on the board's reference ADC input (adc), or dial-gauge readings typed in (manual)")
    p.add_argument("--manual-points", type=ranged(int, 3, 200), default=DEFAULT.manual_points, help="--reference manual: stops per direction (default %(default)s)")
    add_method_arguments(p)
    add_gauge_arguments(p)
    p.add_argument("--duty", type=ranged(int, 100, 6000), default=DEFAULT.duty, help="open-loop duty of the sweeps, of 10000 (default %(default)s: ~13 mm/s)")
    p.add_argument("--levels", type=ranged(int, 3, 50), default=DEFAULT.levels, help="force: loading steps of 5000/N duty each (default %(default)s), "
                   "taken until the gauge reads --force-range")
    p.add_argument("--force-range", type=ranged(float, 1, 25), default=DEFAULT.force_range, metavar="N",
                   help="force: load until the gauge reads this many newtons (default %%(default)s: the paper's forces reach "
                   "15 N); gain: the weight is %d %%%% of it" % round(100 * WEIGHT_FRACTION))
    p.add_argument("--max-duty", type=ranged(int, 100, 10000), default=DEFAULT.max_duty, help="force: largest open-loop duty (default %(default)s)")
    p.add_argument("--anchor-mm", type=ranged(float, -STROKE_LIMIT_MM, STROKE_LIMIT_MM), default=None,
                   help="force: where the fibre goes taut, mm (default 75 %% along the stroke: 45 of 0-60 mm)")
    p.add_argument("--no-flash", action="store_true", help="write the file but do not flash it")
    p.set_defaults(func=run)


def add_guided_arguments(p, yes_help):
    """The options of a guided run on a board, shared with `host experiment`: the board, the
    reference sensor's scale, the force identification's rounds, bringup's fixes, --yes."""
    p.add_argument("--port", default="auto", help=PORT_HELP)
    add_uf2_argument(p)
    p.add_argument("--board", default=None, help="board name or file (default: what the firmware reports; sim: boards/sim.json)")
    p.add_argument("--yes", action="store_true", help=yes_help)
    p.add_argument("--ref-zero-mm", type=ranged(float, -1000, 1000), default=None, help="reference sensor: position at code 0, mm (real boards)")
    p.add_argument("--ref-span-mm", type=ranged(float, 0.001, 10000), default=None, help="reference sensor: travel over its full scale, mm (real boards)")
    p.add_argument("--rounds", type=ranged(int, 1, 20), default=DEFAULT.rounds, help="force: loading/unloading rounds (paper: 5; default %(default)s)")
    p.add_argument("--fix", action="store_true", help="bringup: apply the board-file settings it recommends (wiring, "
                   "directions, oversample for noisy pots): write the corrected board file and flash it, without asking")


PAPER_METHOD = {"model": "bcm", "order": 3, "df_order": 4, "force_order": 2, "gauge_sides": "high", "no_friction": True}


def add_method_arguments(p):
    """The calibration method's options, shared with `host experiment`."""
    p.add_argument("--paper-method", action="store_true",
                   help="the paper's method: BCM-3 pots, a quartic Df, quadratic force fits without friction, gauge "
                   "on the 60 mm side only (same as --model bcm --order 3 --df-order 4 --force-order 2 "
                   "--gauge-sides high --no-friction, and it overrides those options)")
    p.add_argument("--model", default=DEFAULT.model, choices=list(MODELS) + ["auto"], metavar="MODEL", help="pot model: auto (default: the cheapest firmware curve, BCM-3 or a "
                   "free-knot piecewise-linear table, within 0.5 %% of the lowest cross-validated error), bcm, pwl, ... "
                   "(see host fit --help)")
    p.add_argument("--order", type=ranged(int, 1, 64), default=None, help="pot model order (default: bcm 3, pwl 5)")
    p.add_argument("--budget", type=ranged(int, 4, 4096), default=DEFAULT.budget, help="--model auto: most numbers a pot curve may store "
                   "(default %d: a table of up to %d knots)" % (DEFAULT.budget, DEFAULT.budget // 2 + 1))
    p.add_argument("--df-order", type=order_or_auto(12), default=DEFAULT.df_order, help="Df polynomial order 1-12, or auto (default): the paper's 4 unless "
                   "cross-validation finds a higher order more than 5 %% better")
    p.add_argument("--force-order", type=order_or_auto(5), default=DEFAULT.force_order, help="F0(d) and d(F0) order 1-5, or auto (default, cross-validation); "
                   "the paper fits quadratics (2)")
    p.add_argument("--gauge-sides", choices=("high", "low", "both"), default=DEFAULT.gauge_sides,
                   help="force: gauge on the 60 mm side (high: the block pulls toward 0 mm, negative forces, the paper's "
                   "rig), the 0 mm side (low: positive forces), or one after the other (both, default)")
    p.add_argument("--no-friction", action="store_true", help="force: fit F0(d) without the output block's friction "
                   "term (the paper's model); by default the friction is identified and the firmware compensates it")
    p.add_argument("--no-trim", action="store_true", help="force: keep the friction h and F0 the open-loop levels "
                   "identified; by default force mode then holds a few targets against the gauge, trims h to what the "
                   "running loop meets (the block follows the loop's small spring motions) and takes the error left "
                   "at each target out of F0")


def add_gauge_arguments(p):
    """How the force gauge is read, shared with `host experiment`."""
    p.add_argument("--gauge", choices=("display", "adc"), default="display",
                   help="force gauge readings: from its display (typed in on a real bench; default) or from its analog "
                   "output wired to the board's reference ADC input (adc)")
    p.add_argument("--gauge-zero-n", type=ranged(float, -1000, 1000), default=None, help="--gauge adc: force at ADC code 0, N (real boards)")
    p.add_argument("--gauge-span-n", type=ranged(float, 0.001, 100000), default=None, help="--gauge adc: force over the ADC's full scale, N (real boards)")


def make_rig(args, prompter, session):
    from host.guided.rig import Rig, gauge_scale

    scale = gauge_scale(session.actuator, args.gauge_zero_n, args.gauge_span_n) if args.gauge == "adc" else None
    return Rig(prompter, session.virtual, gauge=args.gauge, gauge_scale=scale, adc_bits=session.board["adc_bits"])


def method_options(args):
    """Options fields of the method arguments (PAPER_METHOD applied when --paper-method)."""
    values = {k: getattr(args, k) for k in PAPER_METHOD}
    if args.paper_method:
        values.update(PAPER_METHOD)
    return {"model": values["model"], "order": values["order"], "budget": args.budget,
            "df_order": values["df_order"], "force_order": values["force_order"],
            "gauge_sides": values["gauge_sides"], "friction": not values["no_friction"], "trim": not args.no_trim}


def options_from(args):
    out = Path(args.out)
    plots = Path(args.plots) if args.plots else (out.parent if str(out.parent) else Path("."))
    plots.mkdir(parents=True, exist_ok=True)
    return Options(out=out, out_dir=plots, reference=args.reference, manual_points=args.manual_points,
                   duty=args.duty, anchor_mm=args.anchor_mm, rounds=args.rounds,
                   levels=args.levels, max_duty=args.max_duty, force_range=args.force_range, flash=not args.no_flash, fix=args.fix,
                   **method_options(args))


def calibrate(args, say=None, ask=None, log=None):
    """Run the requested steps; returns {step: StepOutcome} (used by host experiment too). `log`
    (host.guided.run_log.RunLog) records each step's results as it finishes."""
    from host.guided.prompts import Prompter
    from host.guided.rig import reference_scale
    from host.guided.session import Session

    opts = options_from(args)
    steps = (BRINGUP,) + STEPS if args.step == "all" else (args.step,)
    prompter = Prompter(yes=args.yes, ask=ask, out=say)
    say = prompter.say  # one channel for the run's talk: the steps', the session's and flashing's
    with Session(args.port, args.board, opts.out, say=say, uf2=args.uf2) as session:
        if args.yes and session.virtual is None and opts.reference == "manual":
            raise UserError("--yes with --reference manual: nobody to read the dial gauge")
        if args.step == "all":
            done = bringup_done(opts.out, session.board["name"])
            if done:
                steps = STEPS
                say("bringup passed on %s (host calibrate bringup runs it again)" % done.get("date"))
        if ("pots" in steps or BRINGUP in steps) and opts.reference == "adc":
            opts.ref_scale = reference_scale(session.actuator, args.ref_zero_mm, args.ref_span_mm)
        rig = make_rig(args, prompter, session)
        if log:
            log.results["board"] = session.board["name"]
        return run_steps(session, rig, prompter, steps, opts, log=log)


def _stop_log(log, why):
    """Record where the run stopped; a log that cannot be written must not hide why it stopped."""
    try:
        log.stop(why)
    except OSError as exc:
        from host.terminal import warn

        warn("could not write the run log %s: %s" % (log.json_path, exc.strerror or exc))


def _missing_folders(path):
    """The folders above file `path` that do not exist yet, deepest first."""
    out = []
    folder = Path(path).absolute().parent
    while not folder.exists():
        out.append(folder)
        folder = folder.parent
    return out


def _remove_if_empty(folders):
    """Take back the folders this run made, deepest first, where it left nothing in them."""
    for folder in folders:
        try:
            folder.rmdir()
        except OSError:  # not empty (or gone): leave it
            return


def run(args):
    import sys

    from host.guided.run_log import RunLog

    from host.errors import check_output_file

    check_output_file(args.out, "calibration file", make_folders=True)  # before anything is measured
    if args.plots:
        check_output_file(Path(args.plots) / "plot.png", "plot", make_folders=True)
    made = _missing_folders(args.out) + (_missing_folders(Path(args.plots) / "x") if args.plots else [])
    log = RunLog(args.out, "host " + " ".join(sys.argv[1:]) if sys.argv[1:] else "host calibrate")
    try:
        accepted = calibrate(args, log=log)
    except StepRefused as exc:  # a verdict: said in the log, then the usual one line and status 2
        _stop_log(log, str(exc))
        raise
    except (Exception, KeyboardInterrupt) as exc:
        if not log.measured and not isinstance(exc, KeyboardInterrupt):
            # nothing measured (no board, a bad option): the usual one line, and no folder left behind
            _remove_if_empty(sorted(made, key=lambda p: len(p.parts), reverse=True))
            raise
        why = "interrupted (Ctrl-C)" if isinstance(exc, KeyboardInterrupt) else (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        _stop_log(log, why)
        phase = log.results["phase"]
        error("the calibration stopped %s: %s; %s in %s and %s" % (
            "during %s" % phase if phase else "before its first step", why,
            "what it measured is" if log.measured else "the run log is", log.json_path, log.report_path))
        return MISSED
    log.finish()
    output("calibration %s: %s accepted (results: %s)" % (args.out, ", ".join(accepted) or "nothing", log.report_path))
    return DONE if accepted else MISSED
