"""`host experiment paper`: the paper's experiments on a board or `sim`, as a Markdown report."""

from pathlib import Path

from host.commands._options import ranged
from host.commands.calibrate import add_gauge_arguments, add_guided_arguments, add_method_arguments, make_rig, method_options
from host.errors import DONE, MISSED, UserError
from host.terminal import error, output


def add_parser(subparsers):
    p = subparsers.add_parser(
        "experiment",
        help="run the paper's experiments (calibration, Figs. 3a/5/7/8, dead zone, Table 1) and write a report",
        description="Calibrate (pots, assembly, gain, force, as `host calibrate`), then run the paper's "
        "experiments and write DIR/report.md with PNG figures, each number beside the paper's. "
        "With --port sim everything runs on the virtual board (7-8 minutes on a quiet 2-core machine, more beside other work); with --port sim:rp2040 on an emulated Pico.",
    )
    p.add_argument("name", choices=("paper",), help="which experiment set (paper)")
    add_guided_arguments(p, yes_help="no questions (implied with --port sim and sim:rp2040)")
    p.add_argument("--out", required=True, metavar="DIR", help="report directory (report.md, PNGs, calibration files)")
    add_method_arguments(p)
    add_gauge_arguments(p)
    p.add_argument("--held-out-seed", type=ranged(int, 0, 2**31 - 1), default=None, metavar="N",
                   help="seed of the held-out positions and forces (default: drawn from the clock and printed; give "
                   "a run's seed from its results.json to repeat its targets)")
    p.set_defaults(func=run)


def run(args):
    from host.experiments.paper import run_paper, write_stopped
    from host.guided.flow import Options
    from host.guided.prompts import Prompter
    from host.guided.rig import reference_scale
    from host.guided.session import Session

    out_dir = Path(args.out)
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError("cannot create %s: %s" % (out_dir, exc.strerror)) from None
    from host.link.connect import virtual_kind

    prompter = Prompter(yes=args.yes or virtual_kind(args.port) is not None)
    opts = Options(out=out_dir / "calibration.json", out_dir=out_dir, rounds=args.rounds, fix=args.fix,
                   **method_options(args))
    results = {}
    try:
        with Session(args.port, args.board, None, say=prompter.say, uf2=args.uf2) as session:
            opts.ref_scale = reference_scale(session.actuator, args.ref_zero_mm, args.ref_span_mm)
            rig = make_rig(args, prompter, session)
            path, results = run_paper(session, rig, prompter, opts, out_dir, say=prompter.say, results=results,
                                      held_out_seed=args.held_out_seed)
    except (Exception, KeyboardInterrupt) as exc:
        if not results:  # nothing measured yet (no board, a bad option): the usual one line
            raise
        why = "interrupted (Ctrl-C)" if isinstance(exc, KeyboardInterrupt) else (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        phase = results.get("phase", "start")
        path = write_stopped(out_dir, results, phase, why)
        error("the experiment stopped during %s: %s; what it measured is in %s and %s"
              % (phase, why, out_dir / "results.json", path))
        return MISSED
    output("report: %s (%.0f s)" % (path, results["timings"]["total"]))
    return DONE
