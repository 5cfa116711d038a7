"""`host log`: stream telemetry to a CSV file with progress, optionally watched live; Ctrl-C ends
it with a complete file."""

from host.commands._options import add_port_arguments, check_live, live_arguments, open_board, ranged
from host.errors import DONE
from host.link.live_view import watched
from host.link.telemetry_log import CALIBRATED_FIELDS, metadata_path
from host.terminal import end_progress, output, progress_line, warn


def add_parser(subparsers):
    p = subparsers.add_parser("log", help="record telemetry to CSV (Ctrl-C ends cleanly); --live plots it as it comes",
                              description="Stream the board's telemetry records into a CSV file, one column per "
                              "field, with progress (samples, rate, lost frames). Ctrl-C ends it with a complete file. "
                              "A board without calibration sends 0 for positions, deformation and force (it warns "
                              "once); the raw ADC codes are always logged. --live shows the run in a window as it "
                              "comes (closing it ends the log; --keep leaves it open after the log ends); without "
                              "a display, a PNG of the run at the end.")
    add_port_arguments(p)
    p.add_argument("--out", required=True, help="CSV file to write (columns: firmware.telemetry.FIELDS)")
    p.add_argument("--seconds", type=ranged(float, 0.001, 86400), default=None, help="stop after this many seconds of the board's time (its records' clock, as every wait counts; default: until Ctrl-C)")
    p.add_argument("--rate", type=ranged(int, 1, 1000), default=1000, metavar="HZ", help="telemetry rate, Hz (default 1000, at most the board's loop rate)")
    live_arguments(p, with_log=False)
    p.set_defaults(func=run)


def run(args):
    check_live(args)

    def progress(s):
        progress_line("%8d samples  %7.1f/s  lost frames %d  board drops %d" % (s.samples, s.rate, s.lost_frames, s.board_dropped), every=1.0)

    with open_board(args) as board:
        status = board.client.status_info or {}
        if status.get("calibration_crc") is None:
            warn("the board has no usable calibration (%s): %s will be 0; the raw ADC codes (raw1, raw2, raw_ref) are "
                 "logged" % (status.get("calibration_error"), ", ".join(CALIBRATED_FIELDS)))
        _, summary, png, kept = watched(board, args.out, args.rate, args.live,
                                        lambda recording: recording.pump(args.seconds, progress), close_stops=True,
                                        keep=args.keep)
    end_progress()
    output("%s: %s" % (args.out, summary.line()))
    output("metadata (board, firmware, calibration CRC, units, mode and fault codes): %s" % metadata_path(args.out))
    if png:
        output("plot: %s" % png)
    if kept:  # --keep: the file is complete, the board let go; the window is the person's to close
        kept.wait()
    return DONE
