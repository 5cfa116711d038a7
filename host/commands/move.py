"""`host move --to MM`: closed-loop position move of the output block, then motor off."""

from host.board_client import add_port_arguments, open_board, settle
from host.errors import UserError
from host.numbers import ranged
from host.terminal import end_progress, progress_line


def add_parser(subparsers):
    p = subparsers.add_parser("move", help="move the output block to a position (closed loop)")
    add_port_arguments(p)
    p.add_argument("--to", type=ranged(float, -65.5, 65.5), required=True, metavar="MM", help="target position of the output block, mm (0-60)")
    p.add_argument("--tolerance", type=ranged(float, 0.001, 60), default=0.2, metavar="MM", help="settled when within this, mm (default 0.2)")
    p.add_argument("--timeout", type=ranged(float, 0.1, 3600), default=15.0, metavar="S", help="give up after S seconds (default 15)")
    p.add_argument("--hold", action="store_true", help="leave position mode on at the end (the firmware stops the motor "
                   "once heartbeats stop, after host_timeout_ms)")
    p.set_defaults(func=run)


def run(args):
    if not 0.0 <= args.to <= 60.0:
        raise UserError("--to must be within the 0-60 mm stroke")
    target = int(round(args.to * 1000))

    def progress(value, seconds):
        progress_line("%6.2f s  D2 %8.3f mm  (target %.3f mm)" % (seconds, value / 1000, args.to), every=1.0)

    with open_board(args.port, args.board, args.calibration, args.load, require_calibration=True) as board:
        lo, hi = board.call("status").get("stroke_um") or (-65535, 65535)
        if not lo <= target <= hi:
            raise UserError("--to %.3f mm is outside the soft stroke limits in force, %.3f..%.3f mm (the "
                            "stroke_min_um/stroke_max_um parameters, kept stop_margin_um inside the calibrated end "
                            "stops; host status shows both)" % (args.to, lo / 1000, hi / 1000))
        try:
            ok, value, seconds = settle(board, "position", target, "d2_um", int(args.tolerance * 1000), args.timeout, progress=progress)
        finally:
            if not args.hold:
                board.call("stop")
        end_progress()
        status = board.call("status")
    if value is None:
        raise UserError("no telemetry from the board during the move")
    print("%s at %.3f mm (target %.3f mm) after %.2f s%s" % ("reached" if ok else "NOT settled", value / 1000, args.to,
          seconds, "; faults: " + ", ".join(status["faults"]) if status.get("faults") else ""))
    return 0 if ok else 1
