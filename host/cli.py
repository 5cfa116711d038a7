"""The `host` command line: discovers one subcommand per module in `host.commands`."""

import os

# Our least-squares problems are small: on a busy 2-core machine a threaded BLAS makes each solve
# up to 100x slower (measured by bench/bench_compare.py). Set before numpy is first imported.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import importlib
import pkgutil  # noqa: E402
import re  # noqa: E402
import sys  # noqa: E402

import host
import host.commands
from host import terminal
from host.errors import CLOSED_PIPE, DONE, EXIT_STATUSES, INTERRUPTED, USER_ERROR, UserError, os_error_line


class _Parser(argparse.ArgumentParser):
    """A bad option or argument is a user error like any other: one line and exit status 2
    (argparse prints its whole usage block). Subcommand parsers are made of this class too."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        # argparse takes "-1e1" or "-1e300" for an option (its negative numbers are only -5 and
        # -0.5), so `--to -1e1` read as a missing argument; any float literal is a value here
        self._negative_number_matcher = re.compile(r"^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$|^-(inf|infinity|nan)$", re.I)

    def error(self, message):
        self.exit(2, "error: %s (see %s --help)\n" % (message, self.prog))


def build_parser():
    parser = _Parser(
        prog="host",
        description="lsea-kit host tools: fit potentiometer calibrations, talk to the board, "
        "run the guided calibration and the paper's experiments.",
        epilog="exit status, the same for every command: %s." % "; ".join("%d %s" % pair for pair in EXIT_STATUSES),
    )
    parser.add_argument("--version", action="version", version="lsea-kit " + host.__version__)
    parser.add_argument("-q", "--quiet", action="store_true",
                        help="no progress lines on stderr (results, warnings and errors are still printed)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for info in sorted(pkgutil.iter_modules(host.commands.__path__), key=lambda m: m.name):
        if info.name.startswith("_"):  # shared options, not a command
            continue
        module = importlib.import_module("host.commands." + info.name)
        module.add_parser(sub)
    for command in sub.choices.values():  # `host demo --quiet` as well as `host --quiet demo`
        command.add_argument("-q", "--quiet", action="store_true", default=argparse.SUPPRESS,
                             help="no progress lines on stderr")
    return parser


def main(argv=None):
    try:
        code = _main(argv)
        sys.stdout.flush()  # a closed pipe shows here, inside the handler, not at interpreter exit
        return code
    except BrokenPipeError:  # `host status | head -3`: the reader has what it wanted
        try:
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no error at exit's flush
        except (OSError, ValueError):
            pass
        return CLOSED_PIPE


def _main(argv):
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help or --version (0), or a bad option (2, its line printed)
        return exc.code
    if not getattr(args, "func", None):
        parser.print_help()
        return USER_ERROR
    terminal.set_quiet(args.quiet)
    try:
        return args.func(args) or DONE
    except UserError as exc:
        terminal.error(str(exc))
        return USER_ERROR
    except KeyboardInterrupt:
        terminal.interrupted()
        return INTERRUPTED
    except BrokenPipeError:
        raise  # main() ends a closed pipe quietly
    except OSError as exc:  # a serial port gone (serial.SerialException is one), a full disk, a directory for a file
        terminal.error(os_error_line(exc))
        return USER_ERROR


if __name__ == "__main__":
    raise SystemExit(main())
