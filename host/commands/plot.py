"""`host plot run.csv`: positions, deformation, force, duty and targets of a logged run."""

from pathlib import Path

from host.errors import DONE, UserError
from host.link.telemetry_plot import plot
from host.terminal import output, warn


def add_parser(subparsers):
    p = subparsers.add_parser("plot", help="plot a telemetry CSV from host log",
                              description="Plot a telemetry CSV from host log: positions, deformation, force, duty "
                              "and targets. A run from a board without calibration (all those zero) is drawn from "
                              "its raw ADC codes instead, with a warning.")
    p.add_argument("csv", help="the CSV written by host log")
    p.add_argument("--out", default=None, help="PNG to write (default: beside the CSV)")
    p.set_defaults(func=run)


def run(args):
    src = Path(args.csv)  # checked where it is read (telemetry_log.load): missing, a pipe, too large
    out = Path(args.out) if args.out else src.with_suffix(".png")
    try:
        plot(src, out, warn=warn)
    except (ValueError, KeyError) as exc:
        raise UserError("cannot plot %s: %s" % (src, exc))
    output(out)
    return DONE
