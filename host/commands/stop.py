"""`host stop`: motor off, mode idle, and the board ready to move again."""

from host.commands._options import add_port_arguments, open_board
from host.commands.reset import cleared
from host.errors import DONE
from host.terminal import output


def add_parser(subparsers):
    p = subparsers.add_parser(
        "stop", help="stop the motor (mode idle) and clear a host-timeout fault, so the board can move again",
        description="Motor off, mode idle. A host_timeout fault (the host went quiet, e.g. after "
        "`host move --hold`) is cleared too; other faults (a lifted wiper, an exception) are named and "
        "left for `host reset`.")
    add_port_arguments(p)
    p.set_defaults(func=run)


def run(args):
    with open_board(args) as opened:
        board = opened.client
        board.call("stop")
        faults = board.call("status").get("faults") or []
        if faults == ["host_timeout"]:
            output(cleared(board))
        elif faults:
            output("latched: %s (host reset clears them once the cause is fixed)" % ", ".join(faults))
        output("stopped")
    return DONE
