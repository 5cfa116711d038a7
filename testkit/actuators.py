"""Simulated actuators other than boards/sim.json's, for tests and benchmarks.

`with_stroke(board, length_mm, low_mm=0)` is the same actuator built for another stroke: the block's
end stops at `low_mm` and `low_mm + length_mm`, it starts in the middle, each pot's track runs 5 mm past the stroke's
low end and 7 mm past its high end (boards/sim.json: -5 to 67 mm on 0-60), its mounting error keeps
its shape over the new stroke, the reference sensor spans 8 mm more each way, and the gauge's
fibre is anchored 75 % along it. The board file says the stroke too ("stroke_mm"), as a real
actuator's would, so the firmware's soft limits and the host's calibration follow it.

Positions are whole um within +-65.535 mm on the board (firmware/protocol.py POSITION_LIMIT_UM), and
the pot tracks run 7 mm past the stroke's high end, the nut up to 2 mm past the block: so a long
stroke is described with its low end below 0 (`frame_low`: an 80 mm one as -22..58 mm).
"""

import copy


HIGH_END_MAX_MM = 58.0  # a stroke's high end: its pot tracks then end at 65 mm, within the board's positions


def frame_low(length_mm):
    """The low end of a `length_mm` stroke's frame: 0, or below 0 so that it ends at HIGH_END_MAX_MM."""
    return min(0.0, round(HIGH_END_MAX_MM - float(length_mm), 1))


def with_stroke(board, length_mm, low_mm=0.0):
    """A copy of the simulated board `board` (a dict like boards/sim.json) for a
    `low_mm`..`low_mm + length_mm` stroke."""
    b = copy.deepcopy(board)
    a = b["actuator"]
    length, low = float(length_mm), float(low_mm)
    a["block"]["stroke_mm"] = [low, low + length]
    a.setdefault("start", {})["block_mm"] = low + length / 2.0
    for pot in a["pots"].values():
        pot["zero_mm"] = low - 5.0
        pot["track_mm"] = length + 12.0
        pot["mount_error"]["centre_mm"] = low + length / 2.0
        pot["mount_error"]["half_span_mm"] = length / 2.0
    a["reference"]["zero_mm"] = low - 8.0
    a["reference"]["span_mm"] = length + 16.0
    a["gauge"]["anchor_mm"] = round(low + 0.75 * length, 1)
    b["stroke_mm"] = [low, low + length]
    return b
