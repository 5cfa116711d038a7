"""`host stop`: motor off, mode idle."""

from host.board_client import add_port_arguments, open_board


def add_parser(subparsers):
    p = subparsers.add_parser("stop", help="stop the motor (mode idle)")
    add_port_arguments(p)
    p.set_defaults(func=run)


def run(args):
    with open_board(args.port, args.board, args.calibration, args.load) as board:
        board.call("stop")
        print("stopped")
    return 0
