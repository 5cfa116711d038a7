"""`host reset`: name the latched faults, clear them, motor off and mode idle: ready to move."""

from host.link.board_client import add_port_arguments, open_board


def add_parser(subparsers):
    p = subparsers.add_parser("reset", help="clear latched faults (named first); motor off, mode idle")
    add_port_arguments(p)
    p.set_defaults(func=run)


def clear_faults(board):
    """Clear the board's latched faults; returns the lines that say what was cleared."""
    status = board.call("status")
    faults = status.get("faults") or []
    if not faults:
        return ["no latched faults"]
    board.call("reset")
    board.call("status")  # the reset runs after its reply: this reply comes after it
    return ["cleared %s: %s" % (", ".join(faults), status.get("last_fault") or "")]


def run(args):
    with open_board(args.port, args.board, args.calibration, args.load) as board:
        for line in clear_faults(board):
            print(line)
    return 0
