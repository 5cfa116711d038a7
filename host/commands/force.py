"""`host force --target N`: closed-loop force (spring deformation) control, then motor off."""

from host.board_client import BoardError, add_port_arguments, open_board, settle
from host.errors import UserError
from host.numbers import ranged
from host.terminal import end_progress, progress_line


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
    p.set_defaults(func=run)


def _stroke_end(board, d2_um):
    """'0 mm' or '60 mm' when D2 is inside the soft stroke limit's slow zone at that end, else None."""
    try:
        lo, hi = board.call("status")["stroke_um"]  # the limits in force (kept off the end stops)
        zone = board.call("get", "slow_zone_um")
    except (BoardError, KeyError, TypeError, ValueError):  # a firmware without soft stroke limits
        return None
    if d2_um <= lo + zone:
        return "0 mm"
    if d2_um >= hi - zone:
        return "60 mm"
    return None


def run(args):
    target = int(round(args.target * 1000))

    def progress(value, seconds):
        progress_line("%6.2f s  F %8.3f N  (target %.3f N)" % (seconds, value / 1000, args.target), every=1.0)

    last = {}
    with open_board(args.port, args.board, args.calibration, args.load, require_calibration=True) as board:
        try:
            ok, value, seconds = settle(board, "force", target, "force_mN", int(args.tolerance * 1000), args.timeout,
                                        progress=progress, last=last)
        finally:
            if not args.hold:
                board.call("stop")
        end_progress()
        end = _stroke_end(board, last["d2_um"]) if last and not ok else None
    if value is None:
        raise UserError("no telemetry from the board during the force run")
    if not ok:
        why = ("the block ran to D2 = %.1f mm, at the %s stroke end: nothing to push against? hook a load "
               "(--port sim: --load gauge)" % (last["d2_um"] / 1000, end)) if end else \
              "try a longer --timeout or a wider --tolerance"
        raise UserError("force did not settle: %.3f N after %.1f s (target %.3f N); %s" % (value / 1000, seconds, args.target, why))
    print("reached at %.3f N (target %.3f N) after %.2f s" % (value / 1000, args.target, seconds))
    return 0
