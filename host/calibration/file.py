"""The calibration file on the host: build it section by section, write it atomically, read it back.

The format and its checks live in `firmware/calibration.py` (one source of truth, imported
here): an envelope {"format", "schema", "crc32", "payload"} whose payload is a pretty-printed
JSON object (lists of numbers kept on one line), its CRC32 taken over the payload's exact bytes,
so the firmware verifies exactly what was written and a person can read and diff two files.

Writes are atomic: the whole text is serialised first, then written to a temporary file in the
same directory, flushed, fsync'ed and moved over the old file with os.replace (and the directory
fsync'ed), so a crash or an error at any point leaves either the old file or the new one, never a
mix. CalibrationFile is the one way the host's commands change a file: each change is one such
write of the whole document with the other sections kept, and it owns the rules of a change
(new pot curves leave out what was measured through the old ones), the CRC and the dated copy of
the file as it was (set_sections keeps it before its first write). write_calibration alone makes
a whole new document, for files that are nobody's calibration: tests, benches, the experiments'
derived variants in their output directory.
"""

import dataclasses
import datetime
import json
import math
import os
import re
import shutil
import tempfile
import time
from pathlib import Path

from firmware.calibration import (
    FORMAT,
    PAYLOAD_KEY,
    FRICTION_SECTION,
    POLY_SECTIONS,
    POT_SECTIONS,
    SCHEMA,
    STROKE_SECTION,
    FORCE_RANGE_SECTION,
    GAIN_ONE,
    GAIN_SECTION,
    MAX_BYTES,
    OFFSET_SECTION,
    CalibrationError,
    force_range_constants,
    friction_constants,
    gain_constants,
    offset_constants,
    parse_document,
    payload_crc,
    poly_constants,
    pot_constants,
    stroke_constants,
)
from firmware.pwl_fixed import DF_PWL_OFFSET
from host.errors import UserError, check_user_file
from host.calibration.fixed_export import export_force_table, export_poly, export_pot

SECTIONS = POT_SECTIONS + POLY_SECTIONS + (FRICTION_SECTION, STROKE_SECTION, FORCE_RANGE_SECTION, OFFSET_SECTION, GAIN_SECTION)
MAX_FILE_BYTES = 1 << 20  # ours are a few KB (the board reads at most 64 KiB); 1 MiB is no calibration
INFO_KEYS = ("board", "date", "pots")


def _plain(value):
    """JSON-safe copy: numpy scalars to Python, non-finite floats to None (MicroPython's json
    cannot read NaN), tuples to lists."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if hasattr(value, "tolist"):
        return _plain(value.tolist())
    if isinstance(value, bool) or value is None or isinstance(value, (int, str)):
        return value
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    raise TypeError("cannot store %r in a calibration file" % (value,))


def now_iso():
    return datetime.datetime.now(datetime.timezone.utc).replace(microsecond=0).isoformat()


def new_document(board=None, pots=None, date=None):
    """An empty calibration payload: identity only, no sections yet."""
    return {"schema": SCHEMA, "board": board, "pots": dict(pots or {}), "date": date or now_iso()}


def check_sections(doc):
    """Raise UserError if a present section would be refused by the firmware."""
    for name in doc:
        if name not in SECTIONS + INFO_KEYS + ("schema",):
            raise UserError("unknown calibration section %r (known: %s)" % (name, ", ".join(SECTIONS)))
    try:
        for name in POT_SECTIONS:
            if doc.get(name) is not None:
                pot_constants(doc[name], name)
        for name in POLY_SECTIONS:
            poly_constants(doc.get(name), name)
        friction_constants(doc.get(FRICTION_SECTION))
        stroke_constants(doc.get(STROKE_SECTION))
        force_range_constants(doc.get(FORCE_RANGE_SECTION))
        gain_constants(doc.get(GAIN_SECTION))
        offset_constants(doc.get(OFFSET_SECTION))
    except CalibrationError as e:
        raise UserError(str(e)) from None


_NUMBER_LIST = re.compile(r"\[\n\s*(-?[0-9][-+.eE0-9]*(?:,\n\s*-?[0-9][-+.eE0-9]*)*)\n\s*\]")


def _pretty(body):
    """Indented JSON with every list of numbers on one line (a 70-word table stays one line)."""
    text = json.dumps(body, sort_keys=True, ensure_ascii=True, allow_nan=False, indent=1)
    return _NUMBER_LIST.sub(lambda m: "[" + ", ".join(v.strip() for v in m.group(1).split(",")) + "]", text)


def encode_document(doc, check=True):
    """The file text for payload `doc`: the envelope's head on one line, then the payload object
    (CRC over its exact bytes), then the closing brace and a newline. `check=False` skips the
    firmware's section checks (tests make files the board must refuse)."""
    body = _plain(dict(doc, schema=SCHEMA))
    if check:
        check_sections(body)
    payload = _pretty(body)
    head = json.dumps({"format": FORMAT, "schema": SCHEMA, "crc32": payload_crc(payload)}, ensure_ascii=True)
    text = head[:-1] + "," + PAYLOAD_KEY + payload + "\n}\n"
    if check and len(text) > MAX_BYTES:  # the board would refuse the whole file at boot
        raise UserError("the calibration would be %d bytes, more than the %d the board reads (largest sections: %s)" % (
            len(text), MAX_BYTES, ", ".join("%s %d" % (name, size) for size, name in sorted(
                ((len(json.dumps(v)), k) for k, v in body.items()), reverse=True)[:3])))
    return text


def write_calibration(path, doc):
    """Write payload `doc` to `path` atomically; returns the CRC written."""
    path = Path(path)
    text = encode_document(doc)  # any serialisation error happens before the disk is touched
    directory = path.parent if str(path.parent) else Path(".")
    fd, tmp = tempfile.mkstemp(dir=directory, prefix="." + path.name + ".", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="ascii", newline="\n") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise
    try:  # make the rename itself durable
        dfd = os.open(directory, os.O_RDONLY)
        try:
            os.fsync(dfd)
        finally:
            os.close(dfd)
    except OSError:
        pass
    return parse_document(text)[1]


def keep_dated_copy(path):
    """Copy the file at `path` to PATH.YYYYMMDD-HHMMSS.bak beside it before it is replaced: the one
    way a previous calibration (or board file) is kept. Returns the copy's path, or None when there
    was no file. Two copies in one second get -2, -3 ... so none overwrites another."""
    path = Path(path)
    if not path.is_file():
        return None
    stamp = time.strftime("%Y%m%d-%H%M%S")
    backup, n = path.with_name("%s.%s.bak" % (path.name, stamp)), 1
    while backup.exists():
        n += 1
        backup = path.with_name("%s.%s-%d.bak" % (path.name, stamp, n))
    shutil.copy2(path, backup)
    return backup


def read_calibration(path, with_crc=False):
    """The verified payload dict of the calibration file at `path` (UserError if unusable); with
    `with_crc`, (payload, the CRC the firmware reports for it)."""
    path = Path(path)
    check_user_file(path, "calibration file", MAX_FILE_BYTES)
    try:
        raw = path.read_bytes()
    except OSError as e:
        raise UserError("cannot read %s: %s" % (path, e.strerror)) from None
    if not raw.strip():
        raise UserError("calibration file %s is empty (a copy that never finished? the dated .bak beside it, if "
                        "any, is the one before)" % path)
    try:
        body, crc = parse_document(raw.decode("utf-8"))
    except UnicodeDecodeError:
        raise UserError("calibration file %s: not a text file" % path) from None
    except CalibrationError as e:
        raise UserError("calibration file %s: %s" % (path, e)) from None
    return (body, crc) if with_crc else body


def _set_section(doc, name, section):
    """Section `name` of payload `doc` set to `section` (None: removed). A pot section and the
    document's `pots` entry for it name the same pot: a section without a pot_id takes the one the
    document records (a refit of the same pot), and one with a pot_id records it."""
    if name not in SECTIONS:
        raise UserError("unknown calibration section %r (known: %s)" % (name, ", ".join(SECTIONS)))
    if section is None:
        doc.pop(name, None)
        return
    if name in POT_SECTIONS:
        known = (doc.get("pots") or {}).get(name)
        if section.get("pot_id") is None and known is not None:
            section = dict(section, pot_id=known)
        elif section.get("pot_id") is not None:
            doc["pots"] = dict(doc.get("pots") or {}, **{name: section["pot_id"]})
    doc[name] = section


# measured through the pot curves: the end stops in their frame of positions, the rest through D1 and D2
MEASURED_THROUGH_POTS = ("df", "force", "force_inverse", "friction", "stroke", "force_range", OFFSET_SECTION, GAIN_SECTION)


class CalibrationFile:
    """The calibration file at `path`; the one writer of it for the host's commands."""

    def __init__(self, path):
        self.path = Path(path)
        self.backup = None  # the dated copy keep_previous made
        self.left_out = []  # what the last set_sections left out of the file (new pot curves)

    def exists(self):
        return self.path.exists()

    def read(self):
        """The verified payload (UserError when the file is missing or unusable)."""
        return read_calibration(self.path)

    def keep_previous(self):
        """Copy the file as it is now to PATH.YYYYMMDD-HHMMSS.bak beside it, once for this object:
        the copy's path when this call made it, else None (no file, or kept already)."""
        if self.backup is not None or not self.path.is_file():
            return None
        self.backup = keep_dated_copy(self.path)
        return self.backup

    def set_sections(self, sections, board=None, date=None, new_pots=False):
        """Set `sections` ({name: section, or None to remove it}) in one atomic write, the file's
        other sections kept (a missing file starts empty; a corrupt one is refused, UserError,
        unless new pot curves replace it after keep_previous kept it aside). `board` replaces the board's name when given; `date` (default now) is the
        file's. Pot curves among `sections` leave out the end stops measured in the old curves'
        frame of positions (limits from them could sit past a stop); with `new_pots` (new pot
        curves, which a full calibration measures the rest through again) also Df, the force model
        and the friction. `left_out` names what was left out. Returns the CRC the board checks.
        The file as it was is kept first (keep_previous; once for this object): never a lost
        calibration, whoever writes."""
        self.keep_previous()
        try:
            doc = self.read() if self.exists() else new_document(board)
        except UserError:
            if not (new_pots and self.backup is not None):
                raise
            doc = new_document(board)  # new pot curves replace an unreadable file kept aside
        if board is not None:
            doc["board"] = board
        self.left_out = []
        if any(name in POT_SECTIONS for name in sections):
            for name in MEASURED_THROUGH_POTS if new_pots else ("stroke",):
                if name not in sections and doc.get(name) is not None:
                    self.left_out.append(name)
                    doc.pop(name)
        for name, section in sections.items():
            _set_section(doc, name, section)
        doc["date"] = date or now_iso()
        return write_calibration(self.path, doc)


def pot_section(fit, adc_bits, pot_id=None, max_error_um=None, rising=True):
    """A pot section from a FitResult (x in ADC codes, y in mm): float and fixed-point forms.
    `rising` (the default) refuses a curve whose integer positions fall anywhere, which a board
    refuses at boot; False writes any curve (`host fit --force`, file-format tests). A BCM of
    degree below 3 is written after exact degree elevation, since the firmware evaluates degree 3."""
    from host.fitting.rational_bezier import elevate

    if fit.model == "bcm" and fit.order < 3:
        fit = dataclasses.replace(fit, order=3, coefficients=elevate(fit.coefficients, 3),
                                  notes=fit.notes + ["degree %d elevated to 3 (same curve)" % fit.order])
    try:
        kind, fixed = export_pot(fit, adc_bits, max_error_um, rising=rising)
    except ValueError as e:
        raise UserError("cannot export the %s fit for the firmware: %s" % (fit.model, e)) from None
    stats = fit.summary()
    coefficients = stats.pop("coefficients")
    return {
        "kind": kind,
        "adc_bits": int(adc_bits),
        "pot_id": pot_id,
        "model": fit.model,
        "order": int(fit.order),
        "units": ["ADC code", "mm (coefficients)", "um (fixed)"],
        "coefficients": coefficients,
        "fit": stats,
        "fixed": list(fixed),
        "fixed_check": fixed.report(),
    }


def poly_section(coeffs_high_first, x_range, in_scale, out_scale, units, stats=None):
    """A polynomial section (Df, force or its inverse): `units` e.g. ("um", "um") or ("um", "mN")."""
    try:
        fixed = export_poly(coeffs_high_first, x_range[0], x_range[1], in_scale, out_scale)
    except ValueError as e:
        raise UserError("cannot export the polynomial for the firmware: %s" % e) from None
    return {
        "kind": "poly",
        "coefficients": [float(c) for c in coeffs_high_first],
        "x_range": [float(x_range[0]), float(x_range[1])],
        "in_scale": float(in_scale),
        "out_scale": float(out_scale),
        "units": list(units),
        "fit": stats or {},
        "fixed": list(fixed),
        "fixed_check": fixed.report(),
    }


def force_table_section(knots_in, knots_out, in_range, units, stats=None, df=False):
    """A force section as a table (F0(d) or d(F0)), or with `df` the Df section as one: knots in
    natural units (mm, N), `units` as for poly_section."""
    try:
        fixed = export_force_table(knots_in, knots_out, in_range, offset=DF_PWL_OFFSET if df else None, rising=not df,
                                   in_scale=500.0 if df else 1000.0)  # a Df table's input is D1 in 2 um units
    except ValueError as e:
        raise UserError("cannot export the %s table for the firmware: %s" % ("Df" if df else "force", e)) from None
    return {
        "kind": "pwl",
        "knots_in": [float(v) for v in knots_in],
        "knots_out": [float(v) for v in knots_out],
        "in_range": [float(in_range[0]), float(in_range[1])],
        "units": list(units),
        "fit": stats or {},
        "fixed": list(fixed),
        "fixed_check": fixed.report(),
    }


def _d2_table_section(what, d2_mm, values, out_scale, check, fields, stats):
    """A table over D2 (mm, held flat beyond the first and last knot) for the firmware, checked."""
    try:
        fixed = export_force_table(d2_mm, values, (d2_mm[0], d2_mm[-1]), in_scale=500.0, out_scale=out_scale,
                                   offset=DF_PWL_OFFSET, rising=False)
        section = dict({"kind": "pwl", "d2_mm": [float(v) for v in d2_mm]}, **fields)
        section.update({"fit": stats or {}, "fixed": list(fixed), "fixed_check": fixed.report()})
        check(section)
    except (ValueError, CalibrationError) as e:
        raise UserError("cannot export the deformation %s for the firmware: %s" % (what, e)) from None
    return section


def gain_section(d2_mm, gains, stats=None):
    """The deformation gain along the stroke (firmware/measurement.py): `gains` (1 where F0 was
    measured) at positions `d2_mm`."""
    return _d2_table_section("gain", d2_mm, gains, float(GAIN_ONE), gain_constants,
                             {"gain": [float(v) for v in gains]}, stats)


def offset_section(d2_mm, offsets_mm, stats=None):
    """What D1* - D2 still reads at no load (mm) at positions `d2_mm`, for the firmware to take off."""
    return _d2_table_section("offset", d2_mm, offsets_mm, 1000.0, offset_constants,
                             {"offset_mm": [float(v) for v in offsets_mm]}, stats)


def friction_section(friction_n, stats=None, ff_duty=0):
    """The output block's Coulomb friction (N, >= 0) for the firmware's load-force estimate, and
    with `ff_duty` the duty that holds the spring at that force (position control's feed-forward)."""
    fixed = [int(round(max(0.0, friction_n) * 1000.0))]
    if ff_duty:
        fixed.append(int(ff_duty))
    return {"kind": "friction", "friction_n": float(friction_n), "feed_forward_duty": int(ff_duty), "fit": stats or {},
            "fixed": fixed}


def stroke_section(low_mm, high_mm, stats=None):
    """Where the output block's end stops are in its calibrated position D2 (mm): the firmware
    keeps its soft stroke limits `stop_margin_um` inside them."""
    low, high = int(round(low_mm * 1000.0)), int(round(high_mm * 1000.0))
    section = {"kind": "stroke", "end_stops_mm": [float(low_mm), float(high_mm)], "fit": stats or {},
               "fixed": [low, high]}
    try:
        stroke_constants(section)
    except CalibrationError as e:
        raise UserError(str(e)) from None
    return section


def force_range_section(lowest_n, highest_n, stats=None):
    """The forces the force calibration showed the spring and motor hold (N, lowest < 0 < highest):
    force mode refuses a target beyond them (firmware/app.py)."""
    section = {"kind": "force_range", "range_n": [float(lowest_n), float(highest_n)], "fit": stats or {},
               "fixed": [int(round(lowest_n * 1000.0)), int(round(highest_n * 1000.0))]}
    try:
        force_range_constants(section)
    except CalibrationError as e:
        raise UserError(str(e)) from None
    return section
