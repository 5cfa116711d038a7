"""The board's parameter table as the host reads it: names, values, defaults, limits and units.

They come from the board's own table (the `params` command), so the host never carries a second
copy that could disagree with the firmware it talks to, and values are checked against it before
any is set.
"""

from host.errors import UserError


class Param:
    """One row of the board's parameter table."""

    def __init__(self, row):
        self.name, self.value, self.default, self.lo, self.hi, self.unit = row

    def as_dict(self):
        return {"name": self.name, "value": self.value, "default": self.default, "min": self.lo, "max": self.hi,
                "unit": self.unit}


def read_table(board):
    """{name: Param} in the board's order."""
    return {row[0]: Param(row) for row in board.call("params")}


def parse_items(items, table):
    """(names to read, [(name, value)] to set) from NAME and NAME=VALUE words, checked against
    the table; UserError names the first bad word."""
    reads, sets = [], []
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
        p = table[name]
        if not p.lo <= value <= p.hi:
            raise UserError("%s=%d is outside the firmware's limits %d..%d %s" % (name, value, p.lo, p.hi, p.unit))
        sets.append((name, value))
    return reads, sets
