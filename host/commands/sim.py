"""`host sim`: run a virtual board (micropython + the firmware behind a pty) until Ctrl-C."""

import time

from host.virtual_board import DEFAULT_BOARD, LOAD_HELP, VirtualBoard, parse_load


def add_parser(subparsers):
    p = subparsers.add_parser("sim", help="start a virtual board and print its serial device path",
                              description="Start the virtual board: the MicroPython unix port running the firmware "
                              "with the simulated actuator behind a pseudo-terminal. Any tool (host --port, mpremote "
                              "connect, pyserial) can open the printed path. Runs until Ctrl-C.")
    p.add_argument("--board", default=str(DEFAULT_BOARD), help="board file (default boards/sim.json)")
    p.add_argument("--calibration", default=None, help="calibration.json to put on the virtual board's flash")
    p.add_argument("--root", default=None, help="directory to use as the board's flash (default: a temp dir)")
    p.add_argument("--load", type=parse_load, default=None, metavar="none|gauge[@MM]|constant:N", help=LOAD_HELP)
    p.set_defaults(func=run)


def run(args):
    board = VirtualBoard(board=args.board, calibration=args.calibration, root=args.root, load=args.load)
    path = board.start()
    print(path, flush=True)
    print("virtual board running (flash in %s); Ctrl-C to stop" % board.root, flush=True)
    try:
        while True:
            time.sleep(0.5)
    except KeyboardInterrupt:
        pass
    finally:
        board.stop()
    return 0
