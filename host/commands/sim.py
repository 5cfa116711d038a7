"""`host sim`: run a virtual board until Ctrl-C or SIGTERM: the firmware on the MicroPython unix port
(the default) or an emulated Pico (`--chip rp2040`: the Pico's MicroPython on rp2040js)."""

import signal
import time

from host.commands._options import add_load_argument, add_uf2_argument
from host.errors import DONE
from host.link.connect import open_port
from host.terminal import note, output

_STOP_SIGNALS = (signal.SIGTERM, signal.SIGHUP)


class _Stopped(Exception):
    """SIGTERM or SIGHUP arrived: stop the board as Ctrl-C does."""


def add_parser(subparsers):
    p = subparsers.add_parser("sim", help="start a virtual board and print its serial device path: the firmware on the MicroPython "
                                   "unix port, or with --chip rp2040 on an emulated Pico (MicroPython or CircuitPython, --uf2)",
                              description="Start a virtual board behind a pseudo-terminal and print its path: by "
                              "default the MicroPython unix port running the firmware with the simulated actuator; "
                              "with --chip rp2040 an emulated Raspberry Pi Pico (the Pico's own MicroPython, --uf2, "
                              "on the rp2040js emulator) with the simulated actuator wired to the pins of "
                              "boards/pico.json, the firmware installed on it with host flash. Any tool (host --port, "
                              "mpremote connect, pyserial) can open the printed path. Runs until Ctrl-C, SIGTERM or "
                              "SIGHUP.")
    p.add_argument("--chip", choices=("unix", "rp2040"), default="unix",
                   help="unix (default): the MicroPython unix port; rp2040: an emulated Pico")
    p.add_argument("--board", default=None, help="board file (default boards/sim.json; --chip rp2040: boards/pico.json, or boards/pico_circuitpython.json for a CircuitPython UF2)")
    p.add_argument("--calibration", default=None, help="calibration.json to put on the board (--chip rp2040: "
                   "installed with the firmware by host flash; default for boards/sim.json on the unix port: "
                   "boards/sim/calibration.json, the simulated actuator's own)")
    p.add_argument("--uncalibrated", action="store_true", help="start without a calibration, as from the factory")
    p.add_argument("--root", default=None, help="directory to use as the unix-port board's flash (default: a temp dir, "
                   "removed at the end)")
    add_uf2_argument(p, "--chip rp2040")
    p.add_argument("--actuator", default=None, metavar="FILE", help="--chip rp2040: the simulated actuator wired to the "
                   "Pico, a board file with an \"actuator\" section (default boards/sim.json)")
    p.add_argument("--flash-image", default=None, metavar="FILE", help="--chip rp2040: keep the Pico's filesystem in "
                   "this file between runs (created when missing; default: a fresh, empty flash each run)")
    p.add_argument("--no-install", action="store_true", help="--chip rp2040: start with the flash as it is (empty, or "
                   "--flash-image's) instead of installing the firmware; install it yourself with host flash")
    add_load_argument(p, help_prefix="")
    p.set_defaults(func=run)


def _raise_stopped(signum, frame):
    raise _Stopped(signum)


def run(args):
    previous = {s: signal.signal(s, _raise_stopped) for s in _STOP_SIGNALS}  # before anything starts
    where = None
    try:
        # the one door to a board started for a command (host.link.connect.open_port), kept open
        # until a signal: the same board files, calibrations and checks as --port sim / sim:rp2040
        where = open_port("sim:rp2040" if args.chip == "rp2040" else "sim", args.board, args.calibration, args.load,
                          factory=not (args.no_install and args.chip == "rp2040"), uf2=args.uf2, progress=note, ready=not args.uncalibrated,
                          root=args.root, actuator=args.actuator, flash_image=args.flash_image)
        where.open()
        board, path = where.virtual, where.path
        if args.chip == "rp2040":
            what = "emulated Pico (%s)" % board.uf2
        else:
            what = "virtual board (flash in %s) with %s" % (board.root, "calibration %s" % board.calibration
                                                           if board.calibration else "no calibration")
        from host.link.running_sims import register, unregister

        # host ports and --port auto find it while it runs; a guided calibration on its pty mounts its rig
        record = register(path, what, root=getattr(board, "root", None), board=getattr(board, "board_path", None))
        try:
            output(path)
            note("%s running; Ctrl-C to stop" % what)  # stdout carries only the path, for a script to read
            while True:
                time.sleep(0.5)
        finally:
            unregister(record)
    except (KeyboardInterrupt, _Stopped):
        pass
    finally:
        previous.setdefault(signal.SIGINT, signal.getsignal(signal.SIGINT))
        for s in previous:  # a second Ctrl-C or signal must not cut the clean-up short
            signal.signal(s, signal.SIG_IGN)
        try:
            if where is not None:
                where.close()
        finally:
            for s, handler in previous.items():
                signal.signal(s, handler)
    return DONE
