"""`host sim`: run a virtual board until Ctrl-C or SIGTERM: the firmware on the MicroPython unix port
(the default) or an emulated Pico (`--chip rp2040`: the Pico's MicroPython on rp2040js)."""

import signal
import time

from host.commands._options import add_load_argument, add_uf2_argument
from host.errors import DONE
from host.link.virtual_board import DEFAULT_BOARD, VirtualBoard, ready_calibration
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
    add_uf2_argument(p)
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


def _emulated_pico(args):
    from host.link.emulated_pico.board import SIM_BOARD, EmulatedPico, default_board
    from host.link.flashing import flash, resolve_board

    board_path, _ = resolve_board(args.board or str(default_board(args.uf2)))
    pico = EmulatedPico(uf2=args.uf2, board=board_path, actuator=args.actuator or SIM_BOARD,
                        flash_image=args.flash_image, load=args.load, log=note)
    path = pico.start()
    if not args.no_install:
        note("installing the firmware on the emulated Pico with host flash")
        try:
            flash(path, str(board_path), args.calibration, progress=lambda m: note("  " + m), ask_board=False)
        except BaseException:
            pico.stop()
            raise
    return pico, path, "emulated Pico (%s)" % pico.uf2


def run(args):
    previous = {s: signal.signal(s, _raise_stopped) for s in _STOP_SIGNALS}  # before anything starts
    board = None
    try:
        if args.chip == "rp2040":
            board, path, what = _emulated_pico(args)
        else:
            board_path = args.board or str(DEFAULT_BOARD)
            calibration = args.calibration
            if calibration is None and not args.uncalibrated:
                calibration = ready_calibration(board_path)
            board = VirtualBoard(board=board_path, calibration=calibration, root=args.root, load=args.load)
            path = board.start()
            what = "virtual board (flash in %s) with %s" % (board.root, "calibration %s" % calibration if calibration
                                                           else "no calibration")
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
            if board is not None:
                board.stop()
        finally:
            for s, handler in previous.items():
                signal.signal(s, handler)
    return DONE
