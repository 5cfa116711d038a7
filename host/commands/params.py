"""`host params`: list, read and set the firmware's controller parameters, and keep them on the board."""

import json

from host.commands._options import add_port_arguments, open_board
from host.errors import DONE, UserError
from host.link.board_params import check_value
from host.terminal import output


def add_parser(subparsers):
    p = subparsers.add_parser(
        "params", help="list, read or set the firmware's parameters (gains, limits, timeouts); --save keeps them",
        description="Without arguments: every parameter with its value, unit, default and limits. NAME: one value. "
        "NAME=VALUE ...: set them (checked against the board's limits first; nothing is set if one is wrong). "
        "Values set without --save last until the board restarts, or until the host goes silent while the motor "
        "runs (the watchdog then restores the boot values). --save keeps the values in force on the board "
        "(params.txt, loaded at boot; `host status` shows them).")
    p.add_argument("items", nargs="*", metavar="NAME[=VALUE]", help="a parameter to read, or NAME=VALUE to set")
    p.add_argument("--defaults", action="store_true", help="set every parameter back to the firmware's default first")
    p.add_argument("--save", action="store_true", help="keep the values in force on the board (loaded at boot)")
    p.add_argument("--json", action="store_true", help="print the table as JSON")
    add_port_arguments(p)
    p.set_defaults(func=run)


def parse_items(items, table):
    """(names to read, {name: value} to set) from NAME and NAME=VALUE words, checked against
    the table; UserError names the first bad word."""
    reads, sets = [], {}
    for item in items:
        name, eq, text = item.partition("=")
        if name not in table:
            raise UserError("unknown parameter %r (host params lists them: %s)" % (name, ", ".join(table)))
        if not eq:
            reads.append(name)
            continue
        try:
            value = int(text.strip())
        except ValueError:
            raise UserError("%s=%s: the value must be a whole number (in %s)" % (name, text, table[name].unit)) from None
        sets[name] = check_value(table, name, value)
    return reads, sets


def describe(table, saved=None):
    """The table as aligned lines for a person; `saved` ({name: value} or None) marks saved values."""
    saved = saved or {}
    lines = ["%-16s %9s  %-26s %9s  %s" % ("name", "value", "unit", "default", "limits")]
    for p in table.values():
        note = []
        if p.value != p.default:
            note.append("changed")
        if p.name in saved:
            note.append("saved %d" % saved[p.name])
        lines.append("%-16s %9d  %-26s %9d  %d..%d%s" % (
            p.name, p.value, p.unit, p.default, p.lo, p.hi, ("  (" + ", ".join(note) + ")") if note else ""))
    return lines


def run(args):
    with open_board(args) as board:
        table = board.params()
        reads, sets = parse_items(args.items, table)  # all checked before anything is set
        if args.defaults:
            sets = dict({p.name: p.default for p in table.values()}, **sets)
        if sets or args.save:
            table, saved_result = board.set_params(sets, save=args.save)
        else:
            saved_result = None
        status = board.status()
    if reads:
        values = {name: table[name].value for name in reads}
        if args.json:
            output(json.dumps(values))
        else:
            for name in reads:
                output("%s %d %s" % (name, table[name].value, table[name].unit))
        return DONE
    if args.json:
        output(json.dumps({"params": [p.as_dict() for p in table.values()], "saved": status.get("params_saved"),
                          "file_error": status.get("params_file_error")}, indent=1))
        return DONE
    if not sets or args.save or args.defaults:
        output("\n".join(describe(table, status.get("params_saved"))))
    else:
        for name in sets:
            output("%s = %d %s" % (name, table[name].value, table[name].unit))
    if status.get("params_file_error"):
        output("saved parameters not loaded at boot: %s" % status["params_file_error"])
    if saved_result is not None:
        changed = saved_result.get("saved") or {}
        output("saved on the board (%s, loaded at boot): %s" % (
            saved_result.get("file"), ", ".join("%s=%d" % kv for kv in sorted(changed.items())) or "all defaults"))
    elif sets:
        output("not saved: these last until the board restarts (host params --save keeps them)")
    return DONE
