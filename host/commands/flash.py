"""`host flash`: compile and install the firmware, board file and calibration, then verify."""

from host.errors import UserError
from host.link.flashing import flash
from host.link.virtual_board import LOAD_HELP, LOAD_METAVAR, parse_load


def add_parser(subparsers):
    p = subparsers.add_parser("flash", help="install firmware, board file and calibration on a board (mpy-cross + mpremote)",
                              description="Compile the firmware with mpy-cross for the board's architecture, copy it with the "
                              "board file and calibration through mpremote, swap it in with atomic renames, verify CRCs, "
                              "reset and check the firmware answers. Interrupting it leaves the previous install usable.")
    p.add_argument("--port", default="auto",
                   help="serial port (e.g. /dev/ttyACM0), 'sim' for a virtual board, or 'auto' (default: the one board found)")
    p.add_argument("--board", default=None,
                   help="board name in boards/ or a board file path (default: what the board's firmware reports; sim for --port sim)")
    p.add_argument("--replace-board", action="store_true",
                   help="install --board although the firmware on the board reports another board")
    p.add_argument("--calibration", default=None, metavar="FILE", help="calibration.json to install (default: keep the board's)")
    p.add_argument("--load", type=parse_load, default=None, metavar=LOAD_METAVAR,
                   help="for --port sim: " + LOAD_HELP)
    p.set_defaults(func=run)


def run(args):
    def progress(text):
        print(text, flush=True)

    from host.link.ports import resolve

    args.port = resolve(args.port)
    if args.port == "sim":
        from host.link.flashing import resolve_board
        from host.link.virtual_board import VirtualBoard

        board_path, _ = resolve_board(args.board or "sim")
        with VirtualBoard(board=board_path, factory=False, load=args.load) as vb:
            status = flash(vb.path, args.board or "sim", args.calibration, progress=progress, ask_board=False)
    elif args.load is not None:
        raise UserError("--load only applies to --port sim (on a bench, hook the load by hand)")
    else:
        status = flash(args.port, args.board, args.calibration, progress=progress, replace_board=args.replace_board)
    if status.get("version") is None:
        raise UserError("firmware did not report a version")
    print("flashed: firmware %s on %s, calibration %s" % (status["version"], status["board"],
          "%08x" % (status["calibration_crc"] & 0xFFFFFFFF) if status.get("calibration_crc") is not None else "none (%s)" % status.get("calibration_error")))
    return 0
