"""The calibration file on the host: build it section by section, write it atomically, read it back.

The format and its checks live in `firmware/calibration.py` (one source of truth, imported
here): an envelope {"format", "schema", "crc32", "payload"} whose payload is a pretty-printed
JSON object (lists of numbers kept on one line), its CRC32 taken over the payload's exact bytes,
so the firmware verifies exactly what was written and a person can read and diff two files.

Writes are atomic: the whole text is serialised first, then written to a temporary file in the
same directory, flushed, fsync'ed and moved over the old file with os.replace (and the directory
fsync'ed), so a crash or an error at any point leaves either the old file or the new one, never a
mix. `update_section` lets each calibration step (pots, then Df, then force) add its section to
the existing file without losing the others.
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
    CalibrationError,
    friction_constants,
    parse_document,
    payload_crc,
    poly_constants,
    pot_constants,
    stroke_constants,
)
from firmware.pwl_fixed import DF_PWL_OFFSET
from host.errors import UserError, check_user_file
from host.calibration.fixed_export import export_force_table, export_poly, export_pot

SECTIONS = POT_SECTIONS + POLY_SECTIONS + (FRICTION_SECTION, STROKE_SECTION)
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
    return head[:-1] + "," + PAYLOAD_KEY + payload + "\n}\n"


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


def read_calibration(path):
    """The verified payload dict of the calibration file at `path` (UserError if unusable)."""
    path = Path(path)
    check_user_file(path, "calibration file", MAX_FILE_BYTES)
    try:
        raw = path.read_bytes()
    except OSError as e:
        raise UserError("cannot read %s: %s" % (path, e.strerror)) from None
    try:
        body, _ = parse_document(raw.decode("utf-8"))
    except UnicodeDecodeError:
        raise UserError("calibration file %s: not a text file" % path) from None
    except CalibrationError as e:
        raise UserError("calibration file %s: %s" % (path, e)) from None
    return body


def update_section(path, name, section, board=None, pots=None):
    """Set section `name` of the file at `path` (created if missing), keeping all the others.

    A corrupt existing file is refused (UserError), never silently replaced. `board` replaces
    the board identity when given; `pots` ({"pot1": id, ...}) is merged into the file's. A pot
    section and the file's `pots` entry for it name the same pot: a section without a pot_id
    takes the one the file records (a refit of the same pot), and one with a pot_id records it.
    """
    if name not in SECTIONS:
        raise UserError("unknown calibration section %r (known: %s)" % (name, ", ".join(SECTIONS)))
    doc = read_calibration(path) if Path(path).exists() else new_document(board, pots)
    if board is not None:
        doc["board"] = board
    if pots:
        doc["pots"] = dict(doc.get("pots") or {}, **pots)
    set_section(doc, name, section)
    doc["date"] = now_iso()
    write_calibration(path, doc)
    return doc


def set_section(doc, name, section):
    """Section `name` of payload `doc` set to `section`. A pot section and the document's `pots`
    entry for it name the same pot: a section without a pot_id takes the one the document
    records (a refit of the same pot), and one with a pot_id records it."""
    if name in POT_SECTIONS and section is not None:
        known = (doc.get("pots") or {}).get(name)
        if section.get("pot_id") is None and known is not None:
            section = dict(section, pot_id=known)
        elif section.get("pot_id") is not None:
            doc["pots"] = dict(doc.get("pots") or {}, **{name: section["pot_id"]})
    doc[name] = section


MEASURED_THROUGH_POTS = ("df", "force", "force_inverse", "friction", "stroke")


def for_new_pots(old, board=None):
    """The document new pot curves start from: `old`'s pot ids and nothing that was measured
    through its pot curves (Df, the force model, the friction, the end stops). Returns it and the
    names of those sections `old` had."""
    doc = new_document(board=board)
    doc["pots"] = dict((old or {}).get("pots") or {})
    return doc, [name for name in MEASURED_THROUGH_POTS if (old or {}).get(name)]


def write_pot(path, pot, fit, adc_bits, pot_id=None, board=None, rising=True):
    """Write FitResult `fit` as section `pot` of the calibration file at `path` (created if
    missing, the other sections kept), with the pot's and the board's identity when given;
    returns the file's CRC, the one the board will check. A BCM of degree below 3 is written
    after exact degree elevation, since the firmware evaluates degree 3 (bcm3)."""
    from host.fitting.rational_bezier import elevate

    if fit.model == "bcm" and fit.order < 3:
        fit = dataclasses.replace(fit, order=3, coefficients=elevate(fit.coefficients, 3),
                                  notes=fit.notes + ["degree %d elevated to 3 (same curve)" % fit.order])
    update_section(path, pot, pot_section(fit, adc_bits, pot_id=pot_id, rising=rising), board=board)
    return parse_document(Path(path).read_text())[1]


def pot_section(fit, adc_bits, pot_id=None, max_error_um=None, rising=True):
    """A pot section from a FitResult (x in ADC codes, y in mm): float and fixed-point forms.
    `rising` (the default) refuses a curve whose integer positions fall anywhere, which a board
    refuses at boot; False writes any curve (`host fit --force`, file-format tests)."""
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
