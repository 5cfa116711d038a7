"""Options shared by the commands (this module is not a command: host.cli skips `_` modules).

Numeric options refuse what no bench means (NaN, infinities, values outside the range the option
can use) and a bad --load is refused, each as one `error: ...` line from the parser; every board
command takes the same --port and the options of a virtual board started for it.
"""

import argparse
import math

from host.link.port_advice import example_port


def ranged(kind, lo, hi):
    """An argparse type: `kind` (int or float) within [lo, hi]."""

    def parse(text):
        try:
            value = kind(text)
        except (TypeError, ValueError):
            raise argparse.ArgumentTypeError("%r is not %s number" % (text, "a whole" if kind is int else "a")) from None
        if isinstance(value, float) and not math.isfinite(value):
            raise argparse.ArgumentTypeError("%r is not a finite number" % text)
        if not lo <= value <= hi:
            raise argparse.ArgumentTypeError("%s is outside %g..%g" % (text, lo, hi))
        return value

    parse.__name__ = "%s in %g..%g" % (kind.__name__, lo, hi)
    parse.range = (kind, lo, hi)
    return parse


def parsed(parse, name):
    """An argparse type from `parse`, whose ValueError becomes argparse's one-line error."""

    def conv(text):
        try:
            return parse(text)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None

    conv.__name__ = name
    return conv


def order_or_auto(top):
    """An argparse type: "auto" or a whole number within 1..top."""
    whole = ranged(int, 1, top)

    def parse(text):
        if text == "auto":
            return "auto"
        try:
            return whole(text)
        except argparse.ArgumentTypeError:
            raise argparse.ArgumentTypeError("%r is neither auto nor an order 1..%d" % (text, top)) from None

    parse.__name__ = "order 1..%d or auto" % top
    parse.range = whole.range  # a numeric option: tests/cli/test_numbers.py tries it with bad numbers
    return parse


def nonzero(kind):
    """An argparse type: what `kind` accepts, except 0."""

    def parse(text):
        value = kind(text)
        if value == 0:
            raise argparse.ArgumentTypeError("must not be 0")
        return value

    parse.__name__ = "nonzero " + kind.__name__
    parse.range = getattr(kind, "range", None)
    return parse


def load_option(text):
    """An argparse type: a --load description (host.link.bench_load.parse_load)."""
    from host.link.bench_load import parse_load

    try:
        return parse_load(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def add_load_argument(parser, help_prefix="for --port sim or sim:rp2040: "):
    from host.link.bench_load import LOAD_HELP, LOAD_METAVAR

    parser.add_argument("--load", type=load_option, default=None, metavar=LOAD_METAVAR, help=help_prefix + LOAD_HELP)


PORT_HELP = ("serial port of the board (e.g. %s), 'sim' for a virtual board started for this command (the "
             "firmware on the MicroPython unix port), 'sim:rp2040' for an emulated Pico started for it (the Pico's "
             "MicroPython, --uf2, on rp2040js; the firmware installed with host flash), or 'auto' (the default: the "
             "one board `host ports` finds)" % example_port())


def add_uf2_argument(parser, used_with="--port sim:rp2040"):
    from host.link.emulated_pico.board import UF2_HELP

    parser.add_argument("--uf2", default=None, metavar="FILE", help="for %s: %s" % (used_with, UF2_HELP))


def add_port_arguments(parser):
    """--port (and --board/--calibration/--load/--uf2 for a virtual board) shared by the board commands."""
    parser.add_argument("--port", default="auto", help=PORT_HELP)
    parser.add_argument("--board", default=None, help="board file for --port sim (default boards/sim.json; "
                        "sim:rp2040: boards/pico.json)")
    parser.add_argument("--calibration", default=None, help="calibration.json for --port sim or sim:rp2040 (default "
                        "for --port sim on boards/sim.json: boards/sim/calibration.json, the simulated actuator's)")
    parser.add_argument("--uncalibrated", action="store_true",
                        help="--port sim: start the virtual board without a calibration, as from the factory")
    add_load_argument(parser)
    add_uf2_argument(parser)


def open_board(args, **options):
    """The board add_port_arguments' options name, as a host.api.Board (a context manager; closing
    it stops the motor): the one way a board command opens its board. `options`: Board's
    (require_calibration, stop_on_exit)."""
    from host.api import Board

    return Board(args.port, board=args.board, calibration=args.calibration, load=args.load, uf2=args.uf2,
                 uncalibrated=args.uncalibrated, **options)


def live_arguments(parser, with_log=True):
    """--live and --keep (and for a motion command --log FILE and --rate) on a command's parser;
    check_live(args) refuses the combinations that cannot work."""
    if with_log:
        parser.add_argument("--log", default=None, metavar="FILE.csv",
                            help="record the board's telemetry to this CSV while the command runs (same connection; "
                            "RUN.meta.json beside it)")
        parser.add_argument("--rate", type=ranged(int, 1, 1000), default=1000, metavar="HZ",
                            help="--log: telemetry rate, Hz (default 1000)")
    parser.add_argument("--live", action="store_true",
                        help="plot positions, deformation, force, duty and target in a window as they come (10 times a "
                        "second); without a display, a PNG of the run beside the CSV at the end")
    parser.add_argument("--keep", action="store_true",
                        help="with --live: leave the window open after the command ends, until you close it (the "
                        "board is let go and its motor stopped first)")


def check_live(args):
    """A one-line error (host.errors.UserError) for --live or --keep without what they need,
    before any board is opened."""
    from host.errors import UserError

    if args.live and getattr(args, "log", "") is None:  # a motion command's --log; `host log` always has --out
        raise UserError("--live needs --log FILE.csv (the run is recorded while it is shown)")
    if args.keep and not args.live:
        raise UserError("--keep needs --live (it keeps the live window open after the run)")
