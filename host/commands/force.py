"""`host force --target N`: closed-loop force (spring deformation) control, then motor off."""

import sys

from host.board_client import add_port_arguments, open_board, settle


def add_parser(subparsers):
    p = subparsers.add_parser("force", help="hold a force on the output (closed loop on the spring deformation)")
    add_port_arguments(p)
    p.add_argument("--target", type=float, required=True, metavar="N", help="target force, newtons")
    p.add_argument("--tolerance", type=float, default=0.1, metavar="N", help="settled when within this, N (default 0.1)")
    p.add_argument("--timeout", type=float, default=15.0, metavar="S", help="give up after S seconds (default 15)")
    p.add_argument("--hold", action="store_true", help="leave force mode on at the end (until the host timeout)")
    p.set_defaults(func=run)


def run(args):
    target = int(round(args.target * 1000))

    def progress(value, seconds):
        sys.stderr.write("\r%6.2f s  F %8.3f N  (target %.3f N)" % (seconds, value / 1000, args.target))
        sys.stderr.flush()

    with open_board(args.port, args.board, args.calibration, require_calibration=True) as board:
        try:
            ok, value, seconds = settle(board, "force", target, "force_mN", int(args.tolerance * 1000), args.timeout, progress=progress)
        finally:
            if not args.hold:
                board.call("stop")
        sys.stderr.write("\n")
    if value is None:
        print("no telemetry from the board", file=sys.stderr)
        return 1
    print("%s at %.3f N (target %.3f N) after %.2f s" % ("reached" if ok else "NOT settled", value / 1000, args.target, seconds))
    return 0 if ok else 1
