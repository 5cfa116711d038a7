"""`host reset`: name the latched faults, clear them, motor off and mode idle: ready to move."""

from host.commands._options import add_port_arguments
from host.errors import DONE
from host.link.connect import Connection
from host.terminal import output


def add_parser(subparsers):
    p = subparsers.add_parser("reset", help="clear latched faults (named first); motor off, mode idle")
    add_port_arguments(p)
    p.set_defaults(func=run)


def cleared(board):
    """Clear the board's latched faults; the line that says what was cleared."""
    faults, why = board.clear_faults()
    return "cleared %s: %s" % (", ".join(faults), why or "") if faults else "no latched faults"


def run(args):
    with Connection(args.port, args.board, args.calibration, args.load, uf2=args.uf2, ready=not args.uncalibrated) as connection:
        board = connection.client
        output(cleared(board))
    return DONE
