"""`host force --target N`: closed-loop force (spring deformation) control, then motor off; --log
records it over the same connection, --live plots it as it comes."""

from host.commands._options import add_port_arguments, live_arguments, ranged
from host.commands.move import report, run_motion
from host.errors import DONE, MISSED, UserError


def add_parser(subparsers):
    p = subparsers.add_parser("force", help="hold a force on the output (closed loop on the spring deformation)",
                              description="Hold a force on the output block: closed loop on the spring deformation "
                              "(F0(d) of the calibration), until the force stays within --tolerance for 0.3 s, then "
                              "motor off. The block needs something to push against: with nothing on it, force control "
                              "drives it toward a stroke end and it cannot settle. On --port sim, hook a load with "
                              "--load (e.g. --load gauge: negative targets pull against a force gauge).")
    add_port_arguments(p)
    p.add_argument("--target", type=ranged(float, -200, 200), required=True, metavar="N", help="target force, newtons (negative pulls the block toward 0 mm)")
    p.add_argument("--tolerance", type=ranged(float, 0.001, 100), default=0.1, metavar="N", help="settled when within this, N (default 0.1)")
    p.add_argument("--timeout", type=ranged(float, 0.1, 3600), default=15.0, metavar="S", help="give up after S seconds (default 15)")
    p.add_argument("--hold", action="store_true", help="leave force mode on at the end (until the host timeout)")
    live_arguments(p)
    p.add_argument("--json", action="store_true", help="print the outcome as JSON (also when it did not settle)")
    p.set_defaults(func=run)


def run(args):
    outcome, summary, png, kept = run_motion(
        args, lambda board, progress: board.force(args.target, args.tolerance, args.timeout, args.hold, progress),
        "N (F0)")
    if outcome.value is None:
        raise UserError("no telemetry from the board during the force run")
    if not outcome.reached and outcome.stroke_end and not outcome.faults:  # the usual mistake, in its own words
        outcome.cause = ("the block ran to D2 = %.1f mm, at the soft stroke limit (%s): nothing to push against? hook a load "
                         "(--port sim: --load gauge)" % (outcome.last["d2_um"] / 1000, outcome.stroke_end))
    report(args, outcome, summary, png, "%s at %.3f N (target %.3f N) after %.2f s%s" % (
        "reached" if outcome.reached else "NOT settled", outcome.value, args.target, outcome.seconds,
        "" if outcome.reached else ": " + outcome.cause))
    if kept:  # --keep: the outcome is printed, the board let go; the window is the person's to close
        kept.wait()
    return DONE if outcome.reached else MISSED
