"""What a calibration file holds, in words, and how two of them differ (`host show`).

Curves are evaluated with the firmware's own integer evaluators on the numbers the board would
load, so "pot1 differs by 35 um at most" is what the two files would make the board compute.
"""

import numpy as np

from firmware.calibration import (
    FORCE_RANGE_SECTION,
    FRICTION_SECTION,
    POLY_SECTIONS,
    POT_SECTIONS,
    STROKE_SECTION,
    convert,
    force_range_constants,
    friction_constants,
    poly_constants,
    pot_constants,
    stroke_constants,
)
from firmware.poly_fixed import poly
from firmware.pwl_fixed import DF_PWL_OFFSET, FORCE_PWL_OFFSET, df_table_input, pwl

POLY_NAMES = {"df": "Df_hat(D1), assembly error", "force": "F0(d), force of the spring deformation",
              "force_inverse": "d(F0), deformation for a force target"}


def _num(v, fmt="%.4g"):
    return "-" if v is None else fmt % v


def pot_positions_um(section, name):
    """The board's position in um at every ADC code of the pot's ADC."""
    kind, k = pot_constants(section, name)
    bits = int(section.get("adc_bits", 12))
    return np.array([convert(kind, code, k) for code in range(1 << bits)], dtype=float)


def _is_table(section):
    return isinstance(section, dict) and section.get("kind") == "pwl"


def _offset(name):
    return DF_PWL_OFFSET if name == "df" else FORCE_PWL_OFFSET


def _poly_inputs(section, name):
    """(k, inputs): the section's words and 1001 inputs over its range (a table's inputs in the
    section's own units: um or mN, without its offset)."""
    k = poly_constants(section, name)
    scale = 2 if name == "df" else 1  # a Df table's input is D1 in 2 um units
    lo, hi = ((k[2] - _offset(name)) * scale, (k[1 + k[0]] - _offset(name)) * scale) if _is_table(section) else (k[2], k[3])
    return k, np.unique(np.linspace(lo, hi, 1001).round().astype(int))


def evaluate(section, k, x, name="force"):
    """What the board computes for a polynomial or table section `name` at integer input x."""
    if not _is_table(section):
        return poly(int(x), k)
    return pwl(df_table_input(int(x)) if name == "df" else int(x) + FORCE_PWL_OFFSET, k)


def describe_pot(section, name):
    fit = section.get("fit") or {}
    um = pot_positions_um(section, name)
    check = section.get("fixed_check") or {}
    lines = ["%s: %s order %s, %s on the board (%d words)%s" % (
        name, section.get("model", section.get("kind")), section.get("order", "-"), section["kind"], len(section["fixed"]),
        ", pot id %s" % section["pot_id"] if section.get("pot_id") else "")]
    lo, hi = (fit.get("x_range") or [0, len(um) - 1])
    lines.append("  codes %.0f..%.0f -> %.3f..%.3f mm (%d-bit ADC)" % (
        lo, hi, um[int(lo)] / 1000, um[int(hi)] / 1000, int(section.get("adc_bits", 12))))
    if fit:
        lines.append("  fit: rms %s mm, max %s mm over %s samples%s" % (
            _num(fit.get("rms")), _num(fit.get("max_abs")), fit.get("n_samples", "-"),
            "" if fit.get("monotone", True) else ", NOT monotone"))
    if check:
        lines.append("  fixed point: within %s um of the fit (bound %s um)" % (_num(check.get("max_error"), "%.2f"),
                                                                             _num(check.get("bound"), "%.2f")))
    return lines


def describe_poly(section, name):
    k, x = _poly_inputs(section, name)
    units = section.get("units") or ["in", "out"]
    coeffs = section.get("coefficients") or []
    y = np.array([evaluate(section, k, v, name) for v in x])
    shape = "a %d-knot table" % k[0] if _is_table(section) else "degree %d" % (len(coeffs) - 1 if coeffs else k[0])
    lines = ["%s: %s, %s over %s..%s %s -> %s..%s %s" % (
        name, POLY_NAMES.get(name, "polynomial"), shape, x[0], x[-1], units[0], int(y.min()), int(y.max()), units[1])]
    fit = {key: v for key, v in (section.get("fit") or {}).items() if isinstance(v, (int, float)) and not isinstance(v, bool)}
    if fit:
        # a table's "knots" stat counts the fitted ones; the board's table adds its ends carried on to the range
        lines.append("  fit: " + ", ".join("%s %s" % ("fitted knots" if key == "knots" else key, _num(v))
                                           for key, v in sorted(fit.items())[:8]))
    return lines


def describe(doc, crc=None):
    """Lines for a person: identity, then each section."""
    lines = ["board %s, written %s, schema %s%s" % (doc.get("board"), doc.get("date"), doc.get("schema"),
                                                   ", CRC %08x" % crc if crc is not None else "")]
    if doc.get("pots"):
        lines.append("pot ids: " + ", ".join("%s=%s" % kv for kv in sorted(doc["pots"].items())))
    for name in POT_SECTIONS:
        lines += describe_pot(doc[name], name) if doc.get(name) else ["%s: missing" % name]
    for name in POLY_SECTIONS:
        lines += describe_poly(doc[name], name) if doc.get(name) else ["%s: none" % name]
    if doc.get(FRICTION_SECTION):
        k = friction_constants(doc[FRICTION_SECTION])
        lines.append("friction: %.3f N (the output block's Coulomb friction, compensated)%s" % (
            k[0] / 1000.0, "; position control adds %d duty to break the block free" % k[1] if len(k) > 1 else ""))
    else:
        lines.append("friction: none (not compensated)")
    if doc.get(STROKE_SECTION):
        lo, hi = stroke_constants(doc[STROKE_SECTION])
        lines.append("end stops: %.3f and %.3f mm of D2 (stroke %.3f mm; the soft limits stay a margin inside)"
                     % (lo / 1000.0, hi / 1000.0, (hi - lo) / 1000.0))
    else:
        lines.append("end stops: not measured (the soft limits are the stroke_min_um/stroke_max_um parameters alone)")
    if doc.get(FORCE_RANGE_SECTION):
        lo, hi = force_range_constants(doc[FORCE_RANGE_SECTION])
        assumed = (doc[FORCE_RANGE_SECTION].get("fit") or {}).get("assumed") or []
        lines.append("force range: %+.2f .. %+.2f N (what the force step held; force mode refuses targets beyond)%s"
                     % (lo / 1000.0, hi / 1000.0, "; the %s side was not measured and takes the other's" % (
                         "negative" if -1 in assumed else "positive") if assumed else ""))
    else:
        lines.append("force range: not recorded (force mode takes any target within +-200 N)")
    return lines


def _shown(value):
    """A file's metadata value as a person reads it: "not given" for a missing one, a mapping as
    name=value pairs, not Python's None and {}."""
    if value is None or value == {} or value == []:
        return "not given"
    if isinstance(value, dict):
        return ", ".join("%s=%s" % (k, _shown(v)) for k, v in sorted(value.items()))
    return str(value)


def compare(a, b):
    """Lines saying where calibrations `a` and `b` differ, as the board would compute them."""
    lines = []
    same = 0
    for key in ("board", "date", "pots"):
        if a.get(key) != b.get(key):
            lines.append("%s: %s | %s" % (key, _shown(a.get(key)), _shown(b.get(key))))
    for name in POT_SECTIONS + POLY_SECTIONS + (FRICTION_SECTION, STROKE_SECTION, FORCE_RANGE_SECTION):
        sa, sb = a.get(name), b.get(name)
        if not sa and not sb:
            continue
        if not sa or not sb:
            lines.append("%s: only in %s" % (name, "the first" if sa else "the second"))
            continue
        if sa.get("fixed") == sb.get("fixed"):
            lines.append("%s: the same on the board" % name)
            same += 1
            continue
        if name in POT_SECTIONS:
            da, db = pot_positions_um(sa, name), pot_positions_um(sb, name)
            n = min(len(da), len(db))
            diff = np.abs(da[:n] - db[:n])
            worst = int(np.argmax(diff))
            lines.append("%s: %s | %s; positions differ by %.1f um at most (code %d), %.1f um rms" % (
                name, sa.get("model", sa["kind"]), sb.get("model", sb["kind"]), diff[worst], worst, np.sqrt(np.mean(diff**2))))
        elif name in POLY_SECTIONS:
            ka, xa = _poly_inputs(sa, name)
            kb, xb = _poly_inputs(sb, name)
            x = xa[(xa >= max(xa[0], xb[0])) & (xa <= min(xa[-1], xb[-1]))]
            units = (sa.get("units") or ["", ""])[1]
            if len(x):
                diff = np.abs(np.array([evaluate(sa, ka, v, name) - evaluate(sb, kb, v, name) for v in x], dtype=float))
                lines.append("%s: differs by %.0f %s at most over the common inputs %d..%d" % (name, diff.max(), units, x[0], x[-1]))
            else:
                lines.append("%s: the input ranges do not overlap" % name)
        elif name == FRICTION_SECTION:
            fa, fb = friction_constants(sa)[0], friction_constants(sb)[0]
            lines.append("friction: %.3f N | %.3f N" % (fa / 1000.0, fb / 1000.0))
        elif name == FORCE_RANGE_SECTION:
            (la, ha), (lb, hb) = force_range_constants(sa), force_range_constants(sb)
            lines.append("force range: %+.2f..%+.2f N | %+.2f..%+.2f N" % (la / 1000.0, ha / 1000.0, lb / 1000.0, hb / 1000.0))
        else:
            (la, ha), (lb, hb) = stroke_constants(sa), stroke_constants(sb)
            lines.append("end stops: %.3f..%.3f mm | %.3f..%.3f mm" % (la / 1000.0, ha / 1000.0, lb / 1000.0, hb / 1000.0))
    return lines + ["the same calibration"] if len(lines) == same else lines
