"""`host flash`: compile and install the firmware, board file and calibration, then verify."""

from host.commands._options import PORT_HELP, add_uf2_argument, add_load_argument
from host.errors import DONE, UserError
from host.link.connect import Connection
from host.terminal import note, output


def add_parser(subparsers):
    p = subparsers.add_parser("flash", help="check, then install firmware, board file and calibration on a board, atomic and verified "
                                   "(MicroPython: mpy-cross + mpremote; CircuitPython: plain source over the REPL, or --drive "
                                   "onto its mounted CIRCUITPY drive)",
                              description="Compile the firmware with mpy-cross for the board's architecture (CircuitPython: "
                              "its plain source), copy it with the board file and calibration through mpremote, swap it in "
                              "with atomic renames, verify CRCs, reset and check the firmware answers. Interrupting it "
                              "leaves the previous install usable. --drive copies onto a CircuitPython board's mounted "
                              "CIRCUITPY drive instead.")
    p.add_argument("--port", default="auto",
                   help=PORT_HELP)
    add_uf2_argument(p)
    p.add_argument("--board", default=None,
                   help="board name in boards/ or a board file path (default: what the board's firmware reports; sim for --port sim)")
    p.add_argument("--replace-board", action="store_true",
                   help="install --board although the firmware on the board reports another board")
    p.add_argument("--calibration", default=None, metavar="FILE", help="calibration.json to install (default: keep the board's)")
    p.add_argument("--force", action="store_true", help="install a calibration although its readable fields (board, ADC "
                   "width, table knots) contradict its tables or name no board (the board still checks the tables)")
    p.add_argument("--drive", default=None, metavar="DIR",
                   help="a CircuitPython board's mounted CIRCUITPY drive: copy the files onto it (checked first, each "
                        "renamed into place, read back), as its owners install code; needs --board (a CircuitPython "
                        "board file, e.g. pico_circuitpython); CircuitPython reloads by itself")
    add_load_argument(p)
    p.set_defaults(func=run)


def run(args):
    progress = note  # stderr, silenced by --quiet: stdout carries only the result line
    if args.drive is not None:
        from host.link.circuitpy_drive import install

        if args.board is None:
            raise UserError("--drive needs --board (a CircuitPython board file, e.g. pico_circuitpython)")
        written = install(args.drive, args.board, args.calibration, progress=progress, force=args.force)
        output("installed on %s: %d files, verified; CircuitPython reloads code.py by itself (check with host status)"
              % (args.drive, len(written)))
        return DONE
    # check=False: a board may have no firmware yet (a virtual one starts with an empty flash)
    with Connection(args.port, args.board, load=args.load, factory=False, uf2=args.uf2, ready=False,
                    check=False) as connection:
        if connection.virtual is not None:  # nothing to ask: the board file is the virtual board's
            status = connection.reflash(None, args.calibration, progress=progress, ask_board=False, force=args.force)
        else:
            status = connection.reflash(args.board, args.calibration, progress=progress,
                                        replace_board=args.replace_board, force=args.force)
    if status.get("version") is None:
        raise UserError("firmware did not report a version")
    output("flashed: firmware %s on %s, calibration %s" % (status["version"], status["board"],
          "%08x" % (status["calibration_crc"] & 0xFFFFFFFF) if status.get("calibration_crc") is not None else "none (%s)" % status.get("calibration_error")))
    return DONE
