"""The load a person hooks on the output block of a simulated board, as `--load` says it: none,
a force gauge on either side (its fibre taut past an anchor), or a constant force. `parse_load`
turns the text into the rig.json load dict that boards/sim/bench_rig.apply puts on the simulated
actuator (the virtual board's and the emulated Pico's alike)."""

import math

from firmware.board_config import STROKE_LIMIT_MM

LOAD_HELP = ("load on the output block of the virtual board, as hooked on a bench: none (default: the block "
             "runs free, so force control drives it toward a stroke end), gauge[@MM] (a force gauge on the 60 mm "
             "side, its fibre taut below MM, default the board file's anchor, 45 mm on boards/sim.json; negative "
             "force targets pull against it), gauge-low[@MM] (the gauge on the 0 mm side, taut above MM; positive "
             "targets pull against it), or constant:N (N newtons on the block, + toward 60 mm)")
LOAD_METAVAR = "none|gauge[@MM]|gauge-low[@MM]|constant:N"
_GAUGE_SIDES = {"gauge": "high", "gauge-low": "low"}


STROKE_MM = STROKE_LIMIT_MM  # where a gauge's fibre can go taut: somewhere along a stroke the firmware represents
CONSTANT_LOAD_MAX_N = 100  # several times what the actuator can push; beyond it the model's numbers run away


def parse_load(text):
    """`none`, `gauge[@MM]`, `gauge-low[@MM]` or `constant:N` -> the rig.json load dict (bench_rig.apply)."""
    text = str(text).strip()
    kind, sep, value = text.partition("@") if text.startswith("gauge") else text.partition(":")
    try:
        number = float(value) if sep else None
    except ValueError:
        number = math.nan
    if number is None or math.isfinite(number):
        if kind == "none" and not sep:
            return {"kind": "none"}
        if kind in _GAUGE_SIDES and (not sep or -STROKE_MM <= number <= STROKE_MM):
            load = {"kind": "gauge", "side": _GAUGE_SIDES[kind]}
            if sep:
                load["anchor_mm"] = number
            return load
        if kind == "constant" and sep and abs(number) <= CONSTANT_LOAD_MAX_N:
            return {"kind": "constant", "force_n": number}
    raise ValueError("load must be none, gauge[@MM], gauge-low[@MM] or constant:N (MM within +-%g, N within +-%g; "
                     "e.g. gauge@45, constant:-2.5), not %r" % (STROKE_MM, CONSTANT_LOAD_MAX_N, text))
