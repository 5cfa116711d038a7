"""`host show FILE [OTHER]`: what a calibration file holds, in words; with two files, how they differ."""

import json

from host.calibration.file import read_calibration
from host.calibration.report import compare, describe
from host.errors import DONE
from host.terminal import output


def add_parser(subparsers):
    p = subparsers.add_parser(
        "show", help="show what a calibration file holds (models, ranges, fit quality, Df, force, friction); two files: "
        "how they differ",
        description="Reads the file with the firmware's own checks (CRC, every section), then prints each pot's model, "
        "code range and positions, fit quality, the Df and force polynomials, the friction, board, pot ids and date. "
        "With a second file, what differs as the board would compute it (curves evaluated with the firmware's "
        "integer code at every ADC code).")
    p.add_argument("file", help="calibration file")
    p.add_argument("other", nargs="?", default=None, help="a second calibration file to compare with")
    p.add_argument("--json", action="store_true", help="print the payload(s) as JSON")
    p.set_defaults(func=run)


def run(args):
    a, crc = read_calibration(args.file, with_crc=True)  # UserError with one line when it is not a usable calibration
    if args.other is None:
        if args.json:
            output(json.dumps(a, indent=1, sort_keys=True))
        else:
            output("%s:" % args.file)
            output("\n".join("  " + line for line in describe(a, crc)))
        return DONE
    b = read_calibration(args.other)
    if args.json:
        output(json.dumps({"first": a, "second": b}, indent=1, sort_keys=True))
        return DONE
    output("%s | %s:" % (args.file, args.other))
    output("\n".join("  " + line for line in compare(a, b)))
    return DONE
