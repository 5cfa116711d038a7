"""`host move --to MM`: closed-loop position move of the output block, then motor off; --log
records the move's telemetry over the same connection, --live plots it as it comes."""

import json

from firmware.board_config import STROKE_LIMIT_MM
from host.commands._options import add_port_arguments, check_live, live_arguments, open_board, ranged
from host.errors import DONE, MISSED, UserError
from host.link.live_view import watched
from host.terminal import end_progress, output, progress_line


def add_parser(subparsers):
    p = subparsers.add_parser("move", help="move the output block to a position (closed loop)",
                              description="Position mode to --to mm, until the block stays within --tolerance for 0.3 s of the "
                              "board's time or --timeout passed; motor off after unless --hold. --log records the move's "
                              "telemetry, --live shows it.")
    add_port_arguments(p)
    p.add_argument("--to", type=ranged(float, -STROKE_LIMIT_MM, STROKE_LIMIT_MM), required=True, metavar="MM", help="target position of the output block, mm (inside the board's soft stroke limits: host status shows them)")
    p.add_argument("--tolerance", type=ranged(float, 0.001, 60), default=0.2, metavar="MM", help="settled when within this, mm (default 0.2)")
    p.add_argument("--timeout", type=ranged(float, 0.1, 3600), default=15.0, metavar="S", help="give up after S seconds (default 15)")
    p.add_argument("--hold", action="store_true", help="leave position mode on at the end (the firmware stops the motor "
                   "once heartbeats stop, after host_timeout_ms)")
    live_arguments(p)
    p.add_argument("--json", action="store_true", help="print the outcome as JSON")
    p.set_defaults(func=run)


def run_motion(args, motion, unit):
    """Open the board and run `motion(board_or_recording, progress)` -> Settled, logged and
    watched as --log/--live/--keep ask; the progress line shows the value in `unit`. Returns
    (Settled, the log's summary or None, the PNG or None, the live window kept open or None:
    the board is closed by then, and the caller waits on the window after its report)."""
    check_live(args)

    def progress(value, seconds):
        progress_line("%6.2f s  %8.3f %s" % (seconds, value, unit), every=1.0)

    with open_board(args, require_calibration=True, stop_on_exit=not args.hold) as board:
        if args.log:
            outcome, summary, png, kept = watched(board, args.log, args.rate, args.live,
                                                  lambda _: motion(board, progress), keep=args.keep)
        else:
            outcome, summary, png, kept = motion(board, progress), None, None, None
        end_progress()
    return outcome, summary, png, kept


def report(args, outcome, summary, png, text):
    """Print the outcome (JSON with --json) and where the log went."""
    if args.json:
        out = outcome.as_dict()
        if summary is not None:
            out["log"] = {"csv": args.log, "samples": summary.samples, "lost_frames": summary.lost_frames,
                          "board_dropped": summary.board_dropped, "png": None if png is None else str(png)}
        output(json.dumps(out, indent=1))
        return
    output(text)
    if summary is not None:
        output("%s: %s" % (args.log, summary.line()))
    if png:
        output("plot: %s" % png)


def run(args):
    outcome, summary, png, kept = run_motion(
        args, lambda board, progress: board.move(args.to, args.tolerance, args.timeout, args.hold, progress), "mm (D2)")
    if outcome.value is None:
        raise UserError("no telemetry from the board during the move")
    report(args, outcome, summary, png, "%s at %.3f mm (target %.3f mm) after %.2f s%s" % (
        "reached" if outcome.reached else "NOT settled", outcome.value, args.to, outcome.seconds,
        "" if outcome.reached else ": " + outcome.cause))
    if kept:  # --keep: the outcome is printed, the board let go; the window is the person's to close
        kept.wait()
    return DONE if outcome.reached else MISSED
