"""`host reset`: name the latched faults, clear them, motor off and mode idle: ready to move."""

from host.commands._options import add_port_arguments, open_board
from host.errors import DONE
from host.terminal import output


def add_parser(subparsers):
    p = subparsers.add_parser("reset", help="clear latched faults (named first); motor off, mode idle",
                              description="Clear the board's latched faults (each is named first, with the last one's "
                              "text), leaving the motor off and the mode idle. The calibration and saved parameters stay.")
    add_port_arguments(p)
    p.set_defaults(func=run)


def cleared(board):
    """Clear the board's latched faults; the line that says what was cleared."""
    faults, why = board.clear_faults()
    return "cleared %s: %s" % (", ".join(faults), why or "") if faults else "no latched faults"


def run(args):
    with open_board(args) as board:
        output(cleared(board.client))
    return DONE
