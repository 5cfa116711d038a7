"""`host sim`: run a virtual board (micropython + the firmware behind a pty) until Ctrl-C or SIGTERM."""

import signal
import time

from host.commands._options import add_load_argument
from host.link.virtual_board import DEFAULT_BOARD, VirtualBoard

_STOP_SIGNALS = (signal.SIGTERM, signal.SIGHUP)


class _Stopped(Exception):
    """SIGTERM or SIGHUP arrived: stop the board as Ctrl-C does."""


def add_parser(subparsers):
    p = subparsers.add_parser("sim", help="start a virtual board and print its serial device path",
                              description="Start the virtual board: the MicroPython unix port running the firmware "
                              "with the simulated actuator behind a pseudo-terminal. Any tool (host --port, mpremote "
                              "connect, pyserial) can open the printed path. Runs until Ctrl-C, SIGTERM or SIGHUP, "
                              "which stop micropython and remove the temporary flash directory.")
    p.add_argument("--board", default=str(DEFAULT_BOARD), help="board file (default boards/sim.json)")
    p.add_argument("--calibration", default=None, help="calibration.json to put on the virtual board's flash")
    p.add_argument("--root", default=None, help="directory to use as the board's flash (default: a temp dir, removed at the end)")
    add_load_argument(p, help_prefix="")
    p.set_defaults(func=run)


def _raise_stopped(signum, frame):
    raise _Stopped(signum)


def run(args):
    board = VirtualBoard(board=args.board, calibration=args.calibration, root=args.root, load=args.load)
    previous = {s: signal.signal(s, _raise_stopped) for s in _STOP_SIGNALS}
    try:
        path = board.start()
        print(path, flush=True)
        print("virtual board running (flash in %s); Ctrl-C to stop" % board.root, flush=True)
        while True:
            time.sleep(0.5)
    except (KeyboardInterrupt, _Stopped):
        pass
    finally:
        previous.setdefault(signal.SIGINT, signal.getsignal(signal.SIGINT))
        for s in previous:  # a second Ctrl-C or signal must not cut the clean-up short
            signal.signal(s, signal.SIG_IGN)
        try:
            board.stop()
        finally:
            for s, handler in previous.items():
                signal.signal(s, handler)
    return 0
