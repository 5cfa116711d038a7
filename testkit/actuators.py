"""Simulated actuators other than boards/sim.json's, for tests and benchmarks.

`with_stroke(board, length_mm)` is the same actuator built for another stroke: the block's end
stops at 0 and `length_mm`, it starts in the middle, each pot's track runs 5 mm past the stroke's
low end and 7 mm past its high end (boards/sim.json: -5 to 67 mm on 0-60), its mounting error keeps
its shape over the new stroke, the reference sensor spans 8 mm more each way, and the gauge's
fibre is anchored 75 % along it. The board file says the stroke too ("stroke_mm"), as a real
actuator's would, so the firmware's soft limits and the host's calibration follow it.
"""

import copy


def with_stroke(board, length_mm):
    """A copy of the simulated board `board` (a dict like boards/sim.json) for a 0..`length_mm` stroke."""
    b = copy.deepcopy(board)
    a = b["actuator"]
    length = float(length_mm)
    a["block"]["stroke_mm"] = [0.0, length]
    a.setdefault("start", {})["block_mm"] = length / 2.0
    for pot in a["pots"].values():
        pot["zero_mm"] = -5.0
        pot["track_mm"] = length + 12.0
        pot["mount_error"]["centre_mm"] = length / 2.0
        pot["mount_error"]["half_span_mm"] = length / 2.0
    a["reference"]["zero_mm"] = -8.0
    a["reference"]["span_mm"] = length + 16.0
    a["gauge"]["anchor_mm"] = round(0.75 * length, 1)
    b["stroke_mm"] = [0.0, length]
    return b
