"""The calibration file on the board: verify it, then hand the control step its integer constants.

File format (written by host/calibration/file.py), schema 2: a JSON document a person can read,

    {"format": "lsea-kit calibration", "schema": 2, "crc32": <int>,
    "payload": {
     ... the payload object, pretty-printed ...
    }
    }

where `crc32` is binascii.crc32 of the payload's exact bytes: from after `\n"payload": ` up to
the newline before the document's closing brace. The firmware checks the CRC on exactly the
bytes the host wrote, so no re-serialisation is involved (MicroPython's json.dumps orders keys
and spaces differently from CPython's). Schema 1 files (the payload kept as a JSON string in
one line, the CRC over that string) are still read. The payload repeats "schema" so the version
is also covered by the CRC. Payload keys: "schema", "board", "date", "pots" (identity of
pot1/pot2), and the sections "pot1", "pot2" (each {"kind": "bcm3"|"pwl", "fixed": [ints],
...float coefficients, units and fit statistics for people}), and the optional "df", "force",
"force_inverse" (each {"kind": "poly", "fixed": [ints], ...} or absent/null; each may also be a
{"kind": "pwl", ...} table whose input is offset into 0..2**16, by DF_PWL_OFFSET for Df and
FORCE_PWL_OFFSET for the force sections: for a Df that follows the pot tables' kinks, and a
spring whose stiffness changes at a point, see firmware/measurement.py), and the optional
"friction" ({"kind": "friction", "fixed": [h_mN] or [h_mN, ff_duty], ...}: the output block's
Coulomb friction, see firmware/measurement.py, and the duty that makes the motor hold the spring
at that force, which position control adds to break the block free, see firmware/controller.py), and the optional "stroke" ({"kind": "stroke", "fixed": [low_um,
high_um]}: where the output block's end stops are in its calibrated position D2, from which the
controller keeps its soft stroke limits a margin inside, see firmware/controller.py), and the
optional "force_range" ({"kind": "force_range", "fixed": [low_mN, high_mN]}: the forces the force
calibration showed the spring and motor hold, low < 0 < high; force mode refuses a target beyond
them, where F0 is the end of its fit and not a measurement, see firmware/app.py), and the optional
"deformation_gain" ({"kind": "pwl", "fixed": [...]}: a table over D2, input (D2 >> 1) +
DF_PWL_OFFSET as a Df table's, of the factor the deformation D1* - D2 is multiplied by, in
units of 1/GAIN_ONE: pot 2's calibrated curve keeps its mounting error, so a deformation reads
larger or smaller by the curve's slope where the block is, and F0 holds only where it was
measured; see firmware/measurement.py), and the optional "deformation_offset" (the same kind of
table, values in um within +-OFFSET_MAX_UM: what D1* - D2 still reads at no load where the block
is, the part of the assembly error the Df fit left, taken off before the gain).

`load_calibration(path)` returns a `Calibration` or raises `CalibrationError(reason)`; every
integer list is checked for the layout its evaluator needs (lengths, ranges, increasing knots,
non-zero divisors, a proof that each polynomial stays within 31 bits) so a file that passes can
never make the control step divide by zero or leave 31 bits. This module runs unchanged under
CPython; the host imports its checks.
"""

import json
import os
from array import array

import binascii

from firmware.bcm_fixed import invalid as bcm3_invalid
from firmware.bcm_fixed import bcm3
from firmware.poly_fixed import invalid as poly_invalid
from firmware.pwl_fixed import pwl

FORMAT = "lsea-kit calibration"
SCHEMA = 2  # what the host writes; schema 1 is read too
PAYLOAD_KEY = '\n"payload": '  # schema 2: the payload object starts after this
POT_SECTIONS = ("pot1", "pot2")
POLY_SECTIONS = ("df", "force", "force_inverse")
TABLE_SECTIONS = ("df", "force", "force_inverse")  # may be pwl tables instead of polynomials
FRICTION_SECTION = "friction"
STROKE_SECTION = "stroke"
FORCE_RANGE_SECTION = "force_range"
GAIN_SECTION = "deformation_gain"
GAIN_ONE = 16384  # a deformation gain of 1 (the step multiplies, then shifts right by 14)
GAIN_MIN = GAIN_ONE // 2  # 0.5 .. 2: far beyond a pot's slope error, and |d| * gain within 2**30
GAIN_MAX = GAIN_ONE * 2
OFFSET_SECTION = "deformation_offset"
OFFSET_MAX_UM = 2000  # what Df leaves is tens of um; 2 mm would be no residual but a missing Df
STROKE_MAX_UM = 65535  # protocol.POSITION_LIMIT_UM (tested equal; this module stays free of the protocol): positions beyond it are clamped anyway
FRICTION_MAX_MN = 10000  # 10 N: far beyond a slider's friction; keeps h * s + F0 within range
FF_DUTY_MAX = 5000  # half the duty range: a feed-forward beyond it would be a runaway, not friction
LIMIT = 1 << 30
SEGMENT_LIMIT = LIMIT - (1 << 15)  # a pwl segment's dx * |dy|: room left for the rounding offset
MAX_BYTES = 65536  # the largest calibration file the board reads (ours are a few KB)
PWL_VALUE_LIMIT = 1 << 29  # pwl_fixed sign-fixes knot values within [-2**29, 2**29)


class CalibrationError(Exception):
    """The calibration file is missing, corrupt, of another version, or has a bad section."""


def payload_crc(text):
    """CRC32 (unsigned) of the payload string's UTF-8 bytes."""
    return binascii.crc32(text.encode()) & 0xFFFFFFFF


def _envelope(doc):
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise CalibrationError("not an lsea-kit calibration file")
    if doc.get("schema") not in (1, SCHEMA):
        raise CalibrationError("schema version %r not supported (this firmware reads 1 and %d)" % (doc.get("schema"), SCHEMA))
    return doc


def _payload_of(text):
    """(envelope dict, payload text) of a file's text, in either layout."""
    i = text.find(PAYLOAD_KEY)
    if i >= 0:  # schema 2: the envelope's head, then the payload object's own bytes
        end = text.rfind("\n}")
        head = text[:i].rstrip()
        if head.endswith(","):
            head = head[:-1]
        try:
            head = json.loads(head + "}")
        except ValueError:
            raise CalibrationError("not valid JSON")
        doc = _envelope(head)
        if doc["schema"] != 2:
            raise CalibrationError("schema %r file laid out as schema 2" % (doc["schema"],))
        if end < i:  # the envelope's closing brace is gone: the file stops short
            raise CalibrationError("truncated: the file ends inside its payload")
        return doc, text[i + len(PAYLOAD_KEY) : end]
    try:
        doc = json.loads(text)
    except ValueError:
        raise CalibrationError("not valid JSON")
    doc = _envelope(doc)
    if doc["schema"] != 1:
        raise CalibrationError("schema version %r with its payload as a string: not a layout this firmware reads"
                               % (doc["schema"],))
    return doc, doc.get("payload")


def parse_document(text):
    """(payload dict, crc) of a calibration file's text, after checking format, version and CRC."""
    doc, payload = _payload_of(text)
    crc = doc.get("crc32")
    if not isinstance(payload, str) or not isinstance(crc, int):
        raise CalibrationError("payload or crc32 missing")
    if payload_crc(payload) != crc:
        raise CalibrationError("CRC mismatch: the file is corrupted")
    try:
        body = json.loads(payload)
    except ValueError:
        raise CalibrationError("payload is not valid JSON")
    if not isinstance(body, dict) or body.get("schema") != doc["schema"]:
        raise CalibrationError("payload schema does not match the envelope")
    return body, crc


def _int_list(section, name):
    values = section.get("fixed") if isinstance(section, dict) else None
    if not isinstance(values, list) or not values:
        raise CalibrationError("section %s: no fixed-point list" % name)
    for v in values:
        if not isinstance(v, int) or isinstance(v, bool) or v > LIMIT or v < -LIMIT:
            raise CalibrationError("section %s: fixed-point values must be ints within 2**30" % name)
    return values


def _check(ok, name, why):
    if not ok:
        raise CalibrationError("section %s: %s" % (name, why))


def check_bcm3(k, name="bcm3"):
    why = bcm3_invalid(k)  # the layout's limits live with the evaluator
    _check(why is None, name, why)


def check_pwl(k, name="pwl"):
    n = k[0]
    _check(n >= 2 and len(k) == 2 + 2 * n, name, "table length does not match its knot count")
    _check(0 <= k[1] <= 16, name, "bad input shift")
    x = k[2 : 2 + n]
    y = k[2 + n :]
    i = 1
    while i < n:
        dx = x[i] - x[i - 1]
        _check(dx > 0, name, "knot codes must increase")
        _check(dx * abs(y[i] - y[i - 1]) <= SEGMENT_LIMIT, name, "segment too long for 31 bits")
        i += 1
    _check(x[0] >= 0 and x[n - 1] <= 1 << 16, name, "knot codes outside the ADC range")
    _check(-PWL_VALUE_LIMIT <= min(y) and max(y) < PWL_VALUE_LIMIT, name, "knot values beyond 2**29 um")


def check_poly(k, name="poly"):
    why = poly_invalid(k)  # the layout's limits live with the evaluator
    _check(why is None, name, why)


def pot_constants(section, name):
    """(kind, array('i')) of a pot section, checked."""
    values = _int_list(section, name)
    kind = section.get("kind")
    if kind == "bcm3":
        check_bcm3(values, name)
    elif kind == "pwl":
        check_pwl(values, name)
    else:
        raise CalibrationError("section %s: unknown kind %r (bcm3 or pwl)" % (name, kind))
    return kind, array("i", values)


def poly_constants(section, name):
    """array('i') of a polynomial section (or, for the force sections, of a pwl table), checked;
    None when the section is absent."""
    if section is None:
        return None
    kind = section.get("kind", "poly") if isinstance(section, dict) else None
    if kind == "pwl" and name in TABLE_SECTIONS:
        values = _int_list(section, name)
        check_pwl(values, name)
        _check(values[1] == 0, name, "a %s table takes its input unshifted" % name)
        n = values[0]
        if name != "df":  # F0(d) and d(F0) rise: a force target needs a single deformation
            _check(all(values[2 + n + i] < values[3 + n + i] for i in range(n - 1)), name, "a force table must rise")
        return array("i", values)
    if kind != "poly":
        raise CalibrationError("section %s: not a polynomial" % name)
    values = _int_list(section, name)
    check_poly(values, name)
    return array("i", values)


def section_kind(section):
    """'poly' or 'pwl' of a present polynomial-or-table section."""
    return section.get("kind", "poly") if isinstance(section, dict) else "poly"


def friction_constants(section, name=FRICTION_SECTION):
    """array('i', [h_mN] or [h_mN, ff_duty]) of a friction section, checked; None when absent."""
    if section is None:
        return None
    if not isinstance(section, dict) or section.get("kind", "friction") != "friction":
        raise CalibrationError("section %s: not a friction section" % name)
    values = _int_list(section, name)
    _check(len(values) in (1, 2), name, "needs [friction mN] or [friction mN, feed-forward duty]")
    _check(0 <= values[0] <= FRICTION_MAX_MN, name, "friction must be 0..%d mN" % FRICTION_MAX_MN)
    _check(len(values) == 1 or 0 <= values[1] <= FF_DUTY_MAX, name, "feed-forward duty must be 0..%d" % FF_DUTY_MAX)
    _check(len(values) == 1 or values[1] == 0 or values[0] > 0, name, "a feed-forward duty without friction to break")
    return array("i", values)


def stroke_constants(section, name=STROKE_SECTION):
    """array('i', [low_um, high_um]) of the block's end stops, checked; None when absent."""
    if section is None:
        return None
    if not isinstance(section, dict) or section.get("kind", "stroke") != "stroke":
        raise CalibrationError("section %s: not a stroke section" % name)
    values = _int_list(section, name)
    _check(len(values) == 2, name, "needs [low end stop um, high end stop um]")
    _check(-STROKE_MAX_UM <= values[0] < values[1] <= STROKE_MAX_UM, name,
           "end stops must rise and lie within +-%d um" % STROKE_MAX_UM)
    return array("i", values)


def force_range_constants(section, name=FORCE_RANGE_SECTION):
    """array('i', [low_mN, high_mN]) of the forces the calibration held, checked; None when absent."""
    if section is None:
        return None
    if not isinstance(section, dict) or section.get("kind", "force_range") != "force_range":
        raise CalibrationError("section %s: not a force range section" % name)
    values = _int_list(section, name)
    _check(len(values) == 2, name, "needs [lowest force mN, highest force mN]")
    _check(-LIMIT < values[0] < 0 < values[1] < LIMIT, name, "the range must hold 0 (lowest < 0 < highest)")
    return array("i", values)


def _d2_table(section, name, low, high, what):
    """array('i') of a table over D2 whose values lie in low..high, checked; None when absent."""
    if section is None:
        return None
    if not isinstance(section, dict) or section.get("kind") != "pwl":
        raise CalibrationError("section %s: not a table" % name)
    values = _int_list(section, name)
    check_pwl(values, name)
    _check(values[1] == 0, name, "a %s table takes its input unshifted" % name)
    n = values[0]
    _check(all(low <= v <= high for v in values[2 + n :]), name, "%s must be %d..%d" % (what, low, high))
    return array("i", values)


def gain_constants(section, name=GAIN_SECTION):
    """array('i') of a deformation gain table (pwl over D2, in units of 1/GAIN_ONE), checked; None when absent."""
    return _d2_table(section, name, GAIN_MIN, GAIN_MAX, "gains (0.5 to 2 of %d)" % GAIN_ONE)


def offset_constants(section, name=OFFSET_SECTION):
    """array('i') of a deformation offset table (pwl over D2, um), checked; None when absent."""
    return _d2_table(section, name, -OFFSET_MAX_UM, OFFSET_MAX_UM, "offsets (um)")


class Calibration:
    """What the control step needs: pot1/pot2 as (kind, k), df/force/force_inverse as k or None
    (df_kind, force_kind and force_inverse_kind say "poly" or "pwl"), friction as [h_mN] or None, stroke
    as [low_um, high_um] or None, force_range as [low_mN, high_mN] or None, gain and offset as
    deformation gain and offset tables or None. Data only, filled by
    `checked`: the App keeps it after the boot has let this module go (portable.release), and a
    method would keep the whole module alive."""


def checked(body, crc):
    """The Calibration of a payload, every section checked."""
    for name in POT_SECTIONS:
        if name not in body:
            raise CalibrationError("section %s missing (calibrate that pot first)" % name)
    cal = Calibration()
    cal.pot1 = pot_constants(body["pot1"], "pot1")
    cal.pot2 = pot_constants(body["pot2"], "pot2")
    cal.df = poly_constants(body.get("df"), "df")
    cal.force = poly_constants(body.get("force"), "force")
    cal.force_inverse = poly_constants(body.get("force_inverse"), "force_inverse")
    cal.df_kind = section_kind(body.get("df"))
    cal.force_kind = section_kind(body.get("force"))
    cal.force_inverse_kind = section_kind(body.get("force_inverse"))
    cal.friction = friction_constants(body.get(FRICTION_SECTION))
    cal.stroke = stroke_constants(body.get(STROKE_SECTION))
    cal.force_range = force_range_constants(body.get(FORCE_RANGE_SECTION))
    cal.gain = gain_constants(body.get(GAIN_SECTION))
    cal.offset = offset_constants(body.get(OFFSET_SECTION))
    cal.crc = crc
    cal.board = body.get("board")
    cal.date = body.get("date")
    cal.pots = body.get("pots")
    cal.version = body["schema"]
    return cal


def load_calibration(path):
    """The verified `Calibration` in file `path`, or CalibrationError saying what is wrong."""
    try:
        size = os.stat(path)[6]
    except OSError:
        raise CalibrationError("no calibration file at %s" % path)
    if size > MAX_BYTES:  # a huge file must not take the board's heap at boot
        raise CalibrationError("%d bytes, larger than %d: not a calibration this firmware reads" % (size, MAX_BYTES))
    try:
        with open(path, "rb") as f:
            raw = f.read()
    except OSError as exc:  # there, but a directory or unreadable: say so, not "missing"
        raise CalibrationError("cannot read %s (%s)" % (path, exc))
    try:
        text = raw.decode()
    except Exception:  # UnicodeError on CPython, ValueError/UnicodeError on MicroPython
        raise CalibrationError("not a text file")
    body, crc = parse_document(text)
    return checked(body, crc)


def convert(kind, code, k):
    """Position in um of ADC `code` through a pot's (kind, k)."""
    if kind == "bcm3":
        return bcm3(code, k)
    return pwl(code, k)
