"""What a calibration file says in words against what its fixed-point tables make the board do.

The board reads only the "fixed" words of each section (checked by firmware/calibration.py). A
person and the host read the rest: the board it was made for, each pot's ADC width, the knots of
a table in millimetres. A file whose readable fields contradict its tables (edited by hand, made
by another tool, a section pasted from another file) would install and run, and then mislead
whoever reads it; `host flash` refuses one unless told to install it anyway.
"""

import math

import numpy as np

from firmware.calibration import pot_constants
from host.calibration.report import pot_positions_um

# A table's fixed-point error is a few um (fixed_check.max_error), its end knots up to ~50 um off
# the float fit's after the export's monotone and range clamps; 0.2 mm is a contradiction
KNOT_TOLERANCE_UM = 200
EXTRA_KNOTS = 3  # the export pads a table with end knots


def contradictions(doc, board):
    """Lines saying where calibration `doc` (its payload dict) contradicts itself or `board` (the
    board file's dict); [] when its words and its tables agree."""
    out = []
    if not doc.get("board"):
        out.append("it names no board (board is %r): it would install on any board" % (doc.get("board"),))
    for name in (doc.get("pots") or {}):
        if name not in doc:
            out.append("pots names %s, which the file has no section for" % name)
    for name in ("pot1", "pot2"):
        section = doc.get(name)
        if not isinstance(section, dict):
            continue
        bits = section.get("adc_bits")
        if bits is not None and bits != board.get("adc_bits"):
            out.append("%s says adc_bits %r, the board's ADC has %r" % (name, bits, board.get("adc_bits")))
            continue
        out += _knots(section, name)
    return out


def _knots(section, name):
    """A table pot's knots (coefficients.knots_x codes, knots_y mm) against what its fixed words give."""
    coefficients = section.get("coefficients")
    if section.get("kind") != "pwl" or not isinstance(coefficients, dict):
        return []
    xs, ys = coefficients.get("knots_x"), coefficients.get("knots_y")
    if not isinstance(xs, list) or not isinstance(ys, list):
        return []
    if len(xs) != len(ys):
        return ["%s lists %d knot codes and %d knot positions" % (name, len(xs), len(ys))]
    try:
        pairs = [(float(x), float(y)) for x, y in zip(xs, ys)]
    except (TypeError, ValueError):
        return ["%s's knots are not numbers" % name]
    if not all(math.isfinite(x) and math.isfinite(y) for x, y in pairs):
        return ["%s's knots are not finite numbers" % name]
    table_knots = pot_constants(section, name)[1][0]
    # a table of the fit's own knots is padded with end knots, never most of them dropped; one that
    # samples the fit's curve (export_curve_table: when the knots themselves could not be exported,
    # e.g. their integer curve fell somewhere) has as many knots as it needed, and only the
    # positions below can be compared
    sampled = (section.get("fixed_check") or {}).get("sampled") is True
    board_um = pot_positions_um(section, name)
    # the export also splits a segment whose interpolation product would leave 31 bits, on its
    # line (a 2-point line over 80 mm of stroke becomes a 6-knot table): more knots are only
    # extra if the table strays from the listed knots' lines between them
    if not sampled and (len(pairs) - table_knots > EXTRA_KNOTS or
                        table_knots - len(pairs) > EXTRA_KNOTS and _off_the_lines(pairs, board_um) > KNOT_TOLERANCE_UM):
        return ["%s lists %d knots for a table of %d" % (name, len(pairs), table_knots)]
    worst, where = 0.0, None
    last = len(board_um) - 1
    for x, y in pairs:
        # the board reads whole codes: a knot between two of them (the export keeps 1/16 code) says
        # nothing the board contradicts while its position lies between the two codes' positions.
        # Rounding to the nearer code refused a fitted pot whose knee put two knots 0.28 codes and
        # 0.3 mm apart (seed 202611271100)
        below, above = min(max(math.floor(x), 0), last), min(max(math.ceil(x), 0), last)
        lo, hi = sorted((board_um[below], board_um[above]))
        miss = max(lo - y * 1000.0, y * 1000.0 - hi, 0.0)
        if miss > worst:
            worst, where = miss, (x, y, below, above)
    if worst > KNOT_TOLERANCE_UM:
        x, y, below, above = where
        return ["%s's knots say %.6g mm at code %.6g, its table gives %s" % (
            name, y, x, "%.3f mm" % (board_um[below] / 1000.0) if below == above else
            "%.3f-%.3f mm at codes %d-%d" % (board_um[below] / 1000.0, board_um[above] / 1000.0, below, above))]
    return []



def _off_the_lines(pairs, board_um):
    """How far (um) the board's positions stray, at any code, from the lines between the knots
    `pairs` (codes, mm), held flat beyond the end knots as the board's table holds its ends."""
    lines = np.interp(np.arange(len(board_um)), [x for x, _ in pairs], [y * 1000.0 for _, y in pairs])
    return float(np.max(np.abs(np.asarray(board_um, dtype=float) - lines)))
