"""The README's table of commands, made from the command-line parser so that it cannot go stale.

    python -m host.command_table           print it
    python -m host.command_table --write   put it into README.md, between its two markers

tests/cli/test_foundation.py checks that README.md holds exactly what this makes: a command, an
option or a help text changed in host/commands/ fails there until the table is made again.
"""

import argparse
import sys
from pathlib import Path

README = Path(__file__).resolve().parents[1] / "README.md"
BEGIN = "<!-- the command table: made by `python -m host.command_table --write` from the parser; edit the commands' help, not this -->"
END = "<!-- end of the command table -->"
EVERY_COMMAND = ("-h", "--help", "-q", "--quiet")


def _shared_options():
    """{flag: help} of the options every board command takes (host/commands/_options.py), said
    once under the table for the commands that take all of them; the others list their own."""
    from host.commands._options import add_port_arguments

    parser = argparse.ArgumentParser(add_help=False)
    add_port_arguments(parser)
    return dict((max(a.option_strings, key=len), a.help) for a in parser._actions)


def _cell(text):
    return " ".join(text.split()).replace("|", "\\|")


def _commands(parser):
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    helps = {a.dest: a.help for a in sub._choices_actions}
    return [(name, helps.get(name) or "", command) for name, command in sorted(sub.choices.items())]


def _meta(action, default):
    if action.metavar:
        return action.metavar
    return "{%s}" % ",".join(action.choices) if action.choices else default


def _synopsis(command, shared):
    """(the positionals as argparse writes them, the options only this command has)."""
    words, options = [], []
    for action in command._actions:
        if not action.option_strings:
            meta = _meta(action, action.dest)
            words.append({"?": "[%s]", "*": "[%s ...]", "+": "%s ..."}.get(action.nargs, "%s") % meta)
            continue
        flag = max(action.option_strings, key=len)
        if flag in EVERY_COMMAND or shared.get(flag) == action.help:
            continue
        option = flag + (" " + _meta(action, action.dest.upper()) if action.nargs != 0 else "")
        options.append(option if action.required else "[%s]" % option)
    return words, options


def table(parser=None):
    """The Markdown table, with the line that says what every board command also takes."""
    if parser is None:
        from host.cli import build_parser

        parser = build_parser()
    shared = _shared_options()
    lines = ["| command | what it does | its options |", "| --- | --- | --- |"]
    board = []
    for name, help_text, command in _commands(parser):
        own = dict((max(a.option_strings, key=len), a.help) for a in command._actions if a.option_strings)
        takes_all = all(own.get(flag) == text for flag, text in shared.items())
        if takes_all:  # said once under the table; a command with only some of them lists its own
            board.append(name)
        words, options = _synopsis(command, shared if takes_all else {})
        lines.append("| `%s` | %s | %s |" % (_cell(" ".join(["host", name] + words)), _cell(help_text),
                                           " ".join("`%s`" % _cell(o) for o in options)))
    lines.append("")
    lines.append("Board commands (%s) also take `--port PORT` (default `auto`: the one board `host ports` finds; "
                 "`sim` or `sim:rp2040` for a board started for the command, with `--board`, `--calibration`, "
                 "`--uncalibrated`, `--load` and `--uf2`). Every command takes `-q` (no progress lines; results "
                 "stay on stdout, warnings and errors on stderr) and `--help`." % ", ".join(board))
    return "\n".join(lines)


def _span(text):
    """Where the table lies in README text `text`: between the markers (ValueError without them)."""
    try:
        start = text.index(BEGIN) + len(BEGIN)
        return start, text.index(END, start)
    except ValueError:
        raise ValueError("README.md has no command table markers (%s ... %s)" % (BEGIN, END)) from None


def in_readme(text):
    """The table README text `text` holds."""
    start, end = _span(text)
    return text[start:end].strip("\n")


def write(path=README):
    text = path.read_text()
    start, end = _span(text)
    path.write_text(text[:start] + "\n\n" + table() + "\n\n" + text[end:])


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m host.command_table", description=__doc__.split("\n\n")[0])
    ap.add_argument("--write", action="store_true", help="put the table into README.md between its markers")
    args = ap.parse_args(argv)
    if args.write:
        write()
    else:
        print(table())
    return 0


if __name__ == "__main__":
    sys.exit(main())
