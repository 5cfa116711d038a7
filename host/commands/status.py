"""`host status`: what the board runs and its state (firmware, board, calibration, mode, faults)."""

from host.board_client import add_port_arguments, open_board


def add_parser(subparsers):
    p = subparsers.add_parser("status", help="show the board's firmware, calibration, mode and faults")
    add_port_arguments(p)
    p.set_defaults(func=run)


def run(args):
    with open_board(args.port, args.board, args.calibration, args.load) as board:
        status = board.status_info
        for key in ("version", "board", "protocol", "calibration_crc", "calibration_error", "mode", "faults", "last_fault"):
            value = status.get(key)
            if key == "calibration_crc" and value is not None:
                value = "%08x" % (value & 0xFFFFFFFF)
            print("%-18s %s" % (key, value))
    return 0
