"""The firmware's parameters as the board itself describes them (the `params` command): name,
value in force, default, limits and unit. The host carries no second copy of the table that could
disagree with the firmware it talks to; values are checked against the board's own limits before
any is set."""

from host.errors import UserError


class Param:
    """One row of the board's parameter table."""

    def __init__(self, row):
        self.name, self.value, self.default, self.lo, self.hi, self.unit = row

    def as_dict(self):
        return {"name": self.name, "value": self.value, "default": self.default, "min": self.lo, "max": self.hi,
                "unit": self.unit}

    def __repr__(self):
        return "Param(%s=%d %s, default %d, limits %d..%d)" % (self.name, self.value, self.unit, self.default, self.lo,
                                                              self.hi)


def read_table(board):
    """{name: Param} in the board's order."""
    return {row[0]: Param(row) for row in board.call("params")}


def check_value(table, name, value):
    """`value` (an int) for parameter `name`, or a UserError naming what is wrong."""
    if name not in table:
        raise UserError("unknown parameter %r (the board has: %s)" % (name, ", ".join(table)))
    p = table[name]
    if isinstance(value, bool) or not isinstance(value, int):
        raise UserError("%s=%r: the value must be a whole number (in %s)" % (name, value, p.unit))
    if not p.lo <= value <= p.hi:
        raise UserError("%s=%d is outside the firmware's limits %d..%d %s" % (name, value, p.lo, p.hi, p.unit))
    return value


def set_values(board, values, save=False):
    """Set {name: value} on the board, every one checked against its table first (nothing is set
    if one is wrong); with save=True keep the values in force on the board (loaded at boot).
    Returns (the table after, the board's answer to save or None)."""
    table = read_table(board)
    checked = [(name, check_value(table, name, value)) for name, value in values.items()]
    for name, value in checked:
        board.call("set", name, value)
    if checked:
        table = read_table(board)
    return table, board.call("save") if save else None
