"""The controller's parameters in force on a board, and where each value came from.

Four sets of values per parameter of protocol.PARAMS, all int32 arrays in the table's order:
- `defaults`: this board's: the table's, with the soft stroke limits 0.5 mm inside the board
  file's "stroke_mm" when it has one (the table's 0.5/59.5 mm are a 0-60 mm actuator's), and the
  per-step gains and ramps scaled to the board's loop rate (the table's are tuned at 1 kHz);
- `boot`: what the board booted with (saved values, firmware/saved_params.py, else defaults), and
  what a host that goes silent mid-motion gets back;
- `before_temporary`: for each parameter holding a temporary value (`set NAME VALUE temp`: what a
  host command changes for itself, such as the stroke limits a sweep opens or the gains a tuning
  run tries), what it was before; a silent host gets those back;
- the values in force: `p`, the controller's own parameter words (Controller.p), written in place.

The App decides when values go back (App.watch_host, from the safety's state); this module keeps
the values and the rules about them (ranges, a stroke that leaves room to move, saving).
"""

from array import array

from firmware import saved_params
from firmware.protocol import PARAMS

STROKE_INSET_UM = 500  # the soft stroke limits' default distance inside the board file's stroke_mm
PER_STEP_PARAMS = ("ki_pos", "ki_force", "defl_rate_um")  # what a step adds: scaled up below 1 kHz


def index(name):
    """The parameter's place in protocol.PARAMS; ValueError for an unknown name."""
    for i, row in enumerate(PARAMS):
        if row[0] == name:
            return i
    raise ValueError("unknown parameter %r" % (name,))


def board_defaults(board):
    """This board's default for every parameter (see the module's docstring)."""
    defaults = array("i", [row[1] for row in PARAMS])
    stroke = board.get("stroke_mm")
    if stroke is not None:
        defaults[index("stroke_min_um")] = int(round(stroke[0] * 1000)) + STROKE_INSET_UM
        defaults[index("stroke_max_um")] = int(round(stroke[1] * 1000)) - STROKE_INSET_UM
    # the same per second as at 1 kHz (CircuitPython's 250 Hz; docs/circuitpython.md), within each's limit
    loop_hz = board["loop_hz"]
    if loop_hz < 1000:
        for name in PER_STEP_PARAMS:
            i = index(name)
            defaults[i] = min(PARAMS[i][3], (defaults[i] * 1000 + loop_hz // 2) // loop_hz)
    return defaults


class ParamTable:
    def __init__(self, p, board, record):
        """Fill `p` (the controller's parameter words) with the boot values: `record`'s saved
        ones (firmware/records.py; None for nowhere), else the board's defaults."""
        self.p = p
        self.record = record
        self.defaults = board_defaults(board)
        for i in range(len(PARAMS)):
            p[i] = self.defaults[i]
        saved, self.file_error = saved_params.load(record, PARAMS)
        lo_i, hi_i = index("stroke_min_um"), index("stroke_max_um")
        lo, hi = saved.get(lo_i, self.defaults[lo_i]), saved.get(hi_i, self.defaults[hi_i])
        if lo >= hi:  # each in its range, but no position between them: every move would be refused
            self.file_error = "%s unusable: stroke_min_um %d not below stroke_max_um %d" % (record.name, lo, hi)
            saved = {}
        self.from_file = bool(saved)
        for i in saved:
            p[i] = saved[i]
        self.boot = array("i", p)
        self.temporary = array("b", bytes(len(PARAMS)))  # 1 where a temporary value is in force
        self.n_temporary = 0
        self.before_temporary = array("i", p)

    def rows(self):
        """[name, value, default, min, max, unit] per parameter, the values in force."""
        p, d = self.p, self.defaults
        return [[row[0], p[i], d[i], row[2], row[3], row[4]] for i, row in enumerate(PARAMS)]

    def saved(self):
        """{name: value} the board booted with that differ from its defaults; None when no saved
        parameters were loaded."""
        if not self.from_file:
            return None
        b, d = self.boot, self.defaults
        return dict((row[0], b[i]) for i, row in enumerate(PARAMS) if b[i] != d[i])

    def save(self):
        """Keep the values in force in the record (loaded at the next boot); they become the boot
        values, and no value is temporary any more."""
        if self.record is None:
            raise ValueError("this board has no place for saved parameters")
        saved_params.save(self.record, PARAMS, self.p)
        self.file_error = None
        self.from_file = True
        p = self.p
        for i in range(len(p)):
            self.boot[i] = p[i]  # what a silent host gets back from now on
            self.temporary[i] = 0
        self.n_temporary = 0
        return {"file": self.record.name, "saved": self.saved()}

    def set(self, name, value, temporary=False):
        """Check and set one value; `temporary`: it goes back to its value before when the host
        goes silent (restore). A value set without `temporary` stays, and ends any temporary
        value of that parameter."""
        i = index(name)
        value = int(value)
        lo, hi = PARAMS[i][2], PARAMS[i][3]
        if not lo <= value <= hi:
            raise ValueError("%s must be within %d..%d" % (name, lo, hi))
        if name == "stroke_min_um" or name == "stroke_max_um":  # the pair must leave room to move
            other = self.p[index("stroke_max_um" if name == "stroke_min_um" else "stroke_min_um")]
            if (value >= other) if name == "stroke_min_um" else (value <= other):
                raise ValueError("%s %d would leave no stroke: it must be %s stroke_%s_um (%d)" % (
                    name, value, "below" if name == "stroke_min_um" else "above",
                    "max" if name == "stroke_min_um" else "min", other))
        if temporary and not self.temporary[i]:
            self.before_temporary[i] = self.p[i]
            self.temporary[i] = 1
            self.n_temporary += 1
        elif not temporary and self.temporary[i]:
            self.temporary[i] = 0
            self.n_temporary -= 1
        self.p[i] = value

    def temporary_names(self):
        """Names of the parameters that hold a temporary value."""
        return [PARAMS[i][0] for i in range(len(PARAMS)) if self.temporary[i]]

    def changed_names(self):
        """Names of the parameters that differ from their boot values."""
        p = self.p
        return [PARAMS[i][0] for i in range(len(PARAMS)) if p[i] != self.boot[i]]

    def restore(self, to_boot):
        """Every value back to its boot value (`to_boot`), or each temporary one back to its value
        before; no value is temporary afterwards. Returns the names that were changed (those
        differing from boot, or those temporary)."""
        changed = self.changed_names() if to_boot else self.temporary_names()
        back = self.boot if to_boot else self.before_temporary
        p, temp = self.p, self.temporary
        i = 0
        while i < len(p):
            if to_boot or temp[i]:
                p[i] = back[i]
            temp[i] = 0
            i += 1
        self.n_temporary = 0
        return changed
