"""The block's stroke: where the calibration puts the middle, and where the experiments put their
targets and the gauge's anchor.

The paper's actuator runs 0-60 mm; others do not. The nominal stroke is the board file's
"stroke_mm" ([low, high], a real actuator's, as its drawing gives it; the firmware's soft limits
start from it too), else the simulated actuator's block stroke, else 0-60 mm. The pots step
measures the real one: it finds the block's end stops and puts their middle at the middle of the
nominal stroke, so positions mean the same on the board, in the reference's readings and in the
experiments' targets.

Positions are whole micrometres within +-65.535 mm on the board (firmware/protocol.py
POSITION_LIMIT_UM, which measurement.py clamps to), so a stroke must lie within that, with the
pots' tracks and the nut's travel past the block too: a stroke longer than about 58 mm is
described with its low end below 0 (an 80 mm one as -22..58 or -40..40 mm). Positions are then
negative at one end; nothing else changes.
"""

from firmware.board_config import STROKE_LIMIT_MM

DEFAULT_MM = (0.0, 60.0)
LIMIT_MM = STROKE_LIMIT_MM  # |position| the firmware represents (protocol.POSITION_LIMIT_UM)
SWEEP_FRACTION = 0.9  # a pot's sweep must cover this much of the stroke (checks.Limits.min_range_mm)
# the end stops as the reference on a pot reads them, at least this much of the stroke apart
# (checks.Limits.min_stops_mm): a pot's mount error stretches or shrinks its scale, on the drawn
# actuators by up to 2 x 3 mm over 40 mm (testkit/drawn_actuators.py mount_peak_mm)
STOPS_FRACTION = 0.8
ANCHOR_FRACTION = 0.75  # the force gauge's default anchor, along the stroke (45 mm of 60)
ENDS_MM = 1.0  # the displacement targets' first and last, this far inside the stroke
TARGET_STEP_MM = 5.0  # and every 5 mm between (the paper's Fig. 7 targets on 0-60 mm)
# and at least this far inside the soft limits in force: a target on a limit never settles (the
# limit holds the block short of it); 0.5 mm is what the 0-60 mm stroke's 1 and 59 mm leave
LIMIT_MARGIN_MM = 0.5


def nominal(board, actuator=None):
    """(low, high) mm: the board file's "stroke_mm", else `actuator`'s block stroke (a simulated
    one), else DEFAULT_MM."""
    given = (board or {}).get("stroke_mm")
    if given is None and actuator:
        given = (actuator.get("block") or {}).get("stroke_mm")
    if given is None:
        return DEFAULT_MM
    lo, hi = float(given[0]), float(given[1])
    if not -LIMIT_MM <= lo < hi <= LIMIT_MM:
        raise ValueError("stroke_mm must be [low, high] within +-%g mm, not %r (a long stroke starts below 0: "
                         "80 mm as [-22, 58])" % (LIMIT_MM, given))
    return lo, hi


def length(stroke):
    return stroke[1] - stroke[0]


def middle(stroke):
    return (stroke[0] + stroke[1]) / 2.0


def min_sweep_mm(stroke):
    return SWEEP_FRACTION * length(stroke)


def min_stops_mm(stroke):
    return STOPS_FRACTION * length(stroke)


def gauge_anchor_mm(stroke):
    return round(stroke[0] + ANCHOR_FRACTION * length(stroke), 1)


def position_targets(stroke, limits=None):
    """The displacement targets: ENDS_MM inside each end (rounded inward to 0.1 mm) and every
    TARGET_STEP_MM between, on the stroke's own grid, none closer than 1.5 mm to an end target
    (0-60 mm: 1, 5, 10, ..., 55, 59, the paper's). With `limits` (the firmware's soft limits in
    force, mm) the end targets also stay LIMIT_MARGIN_MM inside those."""
    import math

    lo, hi = stroke
    if limits is not None:
        lo = max(lo, limits[0] + LIMIT_MARGIN_MM - ENDS_MM)
        hi = min(hi, limits[1] - LIMIT_MARGIN_MM + ENDS_MM)
    first = math.ceil(round((lo + ENDS_MM) * 10, 6)) / 10
    last = math.floor(round((hi - ENDS_MM) * 10, 6)) / 10
    gap = 0.3 * TARGET_STEP_MM
    out = [first]
    k = math.floor(lo / TARGET_STEP_MM) + 1
    while k * TARGET_STEP_MM <= last - gap:
        v = k * TARGET_STEP_MM
        if v >= first + gap:
            out.append(v)
        k += 1
    out.append(last)
    return tuple(float(v) for v in out)
