"""The calibration file: round trip, corruption never yields wrong numbers, versions, bad
sections, atomic writes, section-by-section updates, and the firmware loader under MicroPython."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from firmware.calibration import CalibrationError, convert, load_calibration, parse_document, payload_crc
from firmware.poly_fixed import poly
from host.calibration.file import (CalibrationFile, new_document, poly_section, pot_section, read_calibration,
                                   stroke_section, write_calibration)
from host.errors import UserError
from host.fitting.fit_result import FitResult
from host.calibration.fixed_export import bcm_float
from testkit.interpreters import REPO, run_micropython

KNEE = {"lx": 60.0, "rx": 3950.0, "weights": [1.0, 12.0, 12.0, 1.0], "handles": [0.0, 1.5, 58.5, 60.0]}
DF = [-1.922222e-6, 2.632e-4, -1.63e-2, 0.46, -4.6]


def bcm_fit(c):
    return FitResult("bcm", 3, 7, c, (c["lx"], c["lx"] + c["rx"]), curve=lambda x: bcm_float(c, x), rms=float("nan"))


def lut_fit():
    c = {"knots_x": [0.0, 1000.0, 3000.0, 4095.0], "knots_y": [0.0, 14.0, 45.0, 60.0]}
    return FitResult("lut", 4, 8, c, (0.0, 4095.0), curve=lambda x: np.interp(x, c["knots_x"], c["knots_y"]))


POT1 = pot_section(bcm_fit(KNEE), 12, pot_id="pot-A")
POT2 = pot_section(lut_fit(), 12, pot_id="pot-B")
DF_SECTION = poly_section(DF, (0.0, 60.0), 1000, 1000, ("um", "um"))


def full_document(board="pico", date="2026-11-22T08:00:00+00:00"):
    doc = new_document(board, {"pot1": "pot-A", "pot2": "pot-B"}, date=date)
    doc.update(pot1=POT1, pot2=POT2, df=DF_SECTION)
    return doc


def numbers(cal):
    """Everything a loaded Calibration would feed the control step."""
    return (cal.pot1[0], list(cal.pot1[1]), cal.pot2[0], list(cal.pot2[1]), cal.df and list(cal.df), cal.force, cal.force_inverse)


@st.composite
def pot_fits(draw):
    """A fit a pot section can hold: a BCM-3 from the fitter's box (a 60 mm pot, either way
    round) or a monotone table over a pot's stroke, with random statistics and notes (any text)."""
    if draw(st.booleans()):
        lx, ux = draw(st.floats(0, 400)), draw(st.floats(3600, 4095))
        handles = [draw(st.floats(-6, 12)), draw(st.floats(-6, 66)), draw(st.floats(-6, 66)), draw(st.floats(48, 66))]
        c = {"lx": lx, "rx": ux - lx, "weights": [1.0] + [60.0 ** draw(st.floats(-1, 1)) for _ in range(3)],
             "handles": handles[::-1] if draw(st.booleans()) else handles}
        fit = bcm_fit(c)
    else:
        xs = sorted(draw(st.lists(st.integers(0, 4095), min_size=2, max_size=12, unique=True)))
        lo, hi = draw(st.floats(-6, 12)), draw(st.floats(48, 66))  # a pot's stroke: 0.5 LSB >= 4 um
        ys = [lo, *sorted(draw(st.lists(st.floats(lo, hi), min_size=len(xs) - 2, max_size=len(xs) - 2))), hi]
        c = {"knots_x": [float(v) for v in xs], "knots_y": ys}
        fit = FitResult("lut", len(xs), len(xs), c, (float(xs[0]), float(xs[-1])),
                        curve=lambda x, c=c: np.interp(x, c["knots_x"], c["knots_y"]))
    fit.rms = draw(st.floats(allow_nan=True, allow_infinity=True))
    fit.n_samples = draw(st.integers(0, 10**6))
    fit.notes = draw(st.lists(st.text(max_size=30), max_size=3))
    return fit


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    board=st.one_of(st.none(), st.text(min_size=0, max_size=20)),
    ids=st.lists(st.one_of(st.none(), st.text(max_size=10)), min_size=2, max_size=2),
    fits=st.lists(pot_fits(), min_size=2, max_size=2),
    with_df=st.booleans(),
)
def test_round_trip(tmp_path, board, ids, fits, with_df):
    doc = new_document(board, {p: i for p, i in zip(("pot1", "pot2"), ids) if i is not None})
    for name, fit, pot_id in zip(("pot1", "pot2"), fits, ids):
        doc[name] = pot_section(fit, 12, pot_id=pot_id, rising=False)  # the format carries any curve
    if with_df:
        doc["df"] = DF_SECTION
    path = tmp_path / "cal.json"
    crc = write_calibration(path, doc)
    back = read_calibration(path)
    assert back["board"] == board and back["pots"] == doc["pots"] and back["date"] == doc["date"]
    for name, fit, pot_id in zip(("pot1", "pot2"), fits, ids):
        section, stored = doc[name], back[name]
        assert stored["pot_id"] == pot_id and stored["kind"] == section["kind"] and stored["model"] == fit.model
        assert stored["coefficients"] == section["coefficients"] and stored["fixed"] == section["fixed"]
        assert stored["fit"]["rms"] == (fit.rms if np.isfinite(fit.rms) else None)  # NaN/inf stored as null
        assert stored["fit"]["notes"] == fit.notes and stored["fit"]["n_samples"] == fit.n_samples
        assert stored["fixed_check"] == section["fixed_check"]
    assert ("df" in back) == with_df
    cal = load_calibration(str(path))
    assert cal.crc == crc and cal.board == board and cal.version == 2 and cal.pots == doc["pots"]
    assert numbers(cal)[:4] == (doc["pot1"]["kind"], doc["pot1"]["fixed"], doc["pot2"]["kind"], doc["pot2"]["fixed"])
    assert (cal.df is not None) == with_df and cal.force is None and cal.force_inverse is None
    # what the board will compute is the fitted curve, within the bound the export promised
    codes = np.arange(0, 4096, 7)
    for (kind, k), fit, section in ((cal.pot1, fits[0], doc["pot1"]), (cal.pot2, fits[1], doc["pot2"])):
        got = np.array([convert(kind, int(x), k) for x in codes])
        assert np.max(np.abs(got - 1000 * fit(np.clip(codes, *fit.x_range)))) <= section["fixed_check"]["bound"]


def test_every_flipped_byte_is_caught_or_harmless(tmp_path):
    path = tmp_path / "cal.json"
    write_calibration(path, full_document())
    good = path.read_bytes()
    expected = numbers(load_calibration(str(path)))
    rng = np.random.default_rng(11)
    caught = harmless = 0
    for i in range(len(good)):
        for mask in (0x01, int(rng.integers(1, 256))):
            bad = bytearray(good)
            bad[i] ^= mask
            path.write_bytes(bytes(bad))
            try:
                got = numbers(load_calibration(str(path)))
            except CalibrationError:
                caught += 1
                with pytest.raises(UserError):
                    read_calibration(path)
                continue
            assert got == expected  # e.g. the trailing newline turned into other whitespace
            harmless += 1
    assert caught > 0.99 * (caught + harmless)


def raw_document(body, schema=1, crc=None):
    payload = json.dumps(body)
    return json.dumps({"format": "lsea-kit calibration", "schema": schema, "crc32": payload_crc(payload) if crc is None else crc, "payload": payload})


@pytest.mark.parametrize(
    "mutate, reason",
    [
        (lambda b: (b, 2, None), "schema version 2"),
        (lambda b: (dict(b, schema=2), 1, None), "payload schema"),
        (lambda b: (b, 1, 12345), "CRC"),
        (lambda b: ({k: v for k, v in b.items() if k != "pot2"}, 1, None), "pot2 missing"),
        (lambda b: (dict(b, pot1=dict(b["pot1"], kind="spline")), 1, None), "unknown kind"),
        (lambda b: (dict(b, pot1=dict(b["pot1"], fixed=b["pot1"]["fixed"][:-1])), 1, None), "bcm3 needs 21"),
        (lambda b: (dict(b, pot1=dict(b["pot1"], fixed=b["pot1"]["fixed"][:9] + [0] + b["pot1"]["fixed"][10:])), 1, None), "weight ratio"),
        (lambda b: (dict(b, pot2=dict(b["pot2"], fixed=[4, 4, 0, 10, 10, 20, 0, 1, 2, 3])), 1, None), "increase"),
        (lambda b: (dict(b, pot2=dict(b["pot2"], fixed=[2, 4, 0, 60000, 0, 60000])), 1, None), "31 bits"),
        (lambda b: (dict(b, df=dict(b["df"], fixed=b["df"]["fixed"][:-2])), 1, None), "degree"),
        (lambda b: (dict(b, df=dict(b["df"], fixed=[1, 0, 0, 1, 0, 1, 3, 1])), 1, None), "Horner shift"),
        # every word within range, but R_1 = 2**28 u / 2**8 leaves 31 bits (tests/firmware/test_poly_fixed.py)
        (lambda b: (dict(b, force=dict(kind="poly", fixed=[2, 0, -30000, 30000, 0, 2**28, 8, 0, 8, 0])), 1, None), "force: Horner step 2 can exceed 31 bits"),
        (lambda b: (dict(b, pot1=dict(b["pot1"], fixed=[2**31] + b["pot1"]["fixed"][1:])), 1, None), "within 2\\*\\*30"),
    ],
)
def test_rejects_bad_documents_with_a_reason(tmp_path, mutate, reason):
    body = json.loads(json.dumps(dict(full_document(), schema=1)))
    path = tmp_path / "cal.json"
    path.write_text(raw_document(*mutate(body)))
    with pytest.raises(CalibrationError, match=reason):
        load_calibration(str(path))


def test_the_file_is_readable_json_and_schema_1_files_are_still_read(tmp_path):
    """Schema 2: the whole file is one JSON document whose payload is an object a person can
    read (one key per line, number lists on one line); the CRC covers the payload's exact bytes.
    A schema 1 file (the payload as a one-line string) still loads, with the same numbers."""
    path = tmp_path / "cal.json"
    doc = full_document()
    write_calibration(path, doc)
    text = path.read_text()
    whole = json.loads(text)
    assert whole["schema"] == 2 and whole["payload"]["pot1"]["fixed"] == doc["pot1"]["fixed"]
    assert len(text.splitlines()) > 20 and max(len(line) for line in text.splitlines() if '"fixed"' not in line) < 200
    old = tmp_path / "old.json"
    old.write_text(raw_document(json.loads(json.dumps(dict(full_document(), schema=1)))))
    assert "\n" not in old.read_text().strip()
    assert numbers(load_calibration(str(old))) == numbers(load_calibration(str(path)))
    assert read_calibration(old)["pot1"]["fixed"] == doc["pot1"]["fixed"]


def test_missing_and_non_json_files(tmp_path):
    with pytest.raises(CalibrationError, match="no calibration file"):
        load_calibration(str(tmp_path / "nope.json"))
    with pytest.raises(UserError, match="no calibration file"):
        read_calibration(tmp_path / "nope.json")
    (tmp_path / "x.json").write_bytes(b"\xff\xfe{")
    with pytest.raises(CalibrationError):
        load_calibration(str(tmp_path / "x.json"))
    (tmp_path / "y.json").write_text("[1, 2")
    with pytest.raises(CalibrationError, match="JSON"):
        load_calibration(str(tmp_path / "y.json"))


def test_failed_serialisation_leaves_the_old_file(tmp_path, monkeypatch):
    path = tmp_path / "cal.json"
    write_calibration(path, full_document(board="old"))
    before = path.read_bytes()

    def broken(*args, **kwargs):
        raise RuntimeError("disk full, say")

    monkeypatch.setattr("host.calibration.file.os.fsync", broken)
    with pytest.raises(RuntimeError):
        write_calibration(path, full_document(board="new"))
    assert path.read_bytes() == before
    assert sorted(os.listdir(tmp_path)) == ["cal.json"], "the temporary file must be cleaned up"
    with pytest.raises(TypeError):
        write_calibration(path, dict(full_document(), board=object()))  # not serialisable
    assert path.read_bytes() == before


def test_killed_writer_leaves_the_old_file(tmp_path):
    """A process killed after writing the temporary file but before the rename: old file intact."""
    path = tmp_path / "cal.json"
    write_calibration(path, full_document(board="old"))
    before = path.read_bytes()
    script = (
        "import os, signal, sys\n"
        "sys.path.insert(0, %r)\n"
        "sys.path.insert(0, %r)\n"
        "import host.calibration.file as cf\n"
        "os.replace = lambda a, b: os.kill(os.getpid(), signal.SIGKILL)\n"
        "cf.write_calibration(%r, cf.new_document(board='new'))\n" % (str(REPO), str(REPO / "tests"), str(path))
    )
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
    assert proc.returncode == -9, proc.stderr
    assert path.read_bytes() == before
    assert read_calibration(path)["board"] == "old"


def test_pot_identity_follows_its_section(tmp_path):
    cal = CalibrationFile(tmp_path / "cal.json")
    cal.set_sections({"pot1": dict(POT1, pot_id="S-1")}, board="rig-2")
    cal.set_sections({"pot1": dict(POT1, pot_id=None)})  # a refit of the same pot keeps its id
    doc = cal.read()
    assert doc["board"] == "rig-2" and doc["pots"] == {"pot1": "S-1"} and doc["pot1"]["pot_id"] == "S-1"
    cal.set_sections({"pot1": dict(POT1, pot_id="S-9")})  # a new pot replaces it
    doc = cal.read()
    assert doc["pots"] == {"pot1": "S-9"} and doc["pot1"]["pot_id"] == "S-9" and doc["board"] == "rig-2"


def test_a_change_keeps_the_other_sections(tmp_path):
    path = tmp_path / "cal.json"
    cal = CalibrationFile(path)
    cal.set_sections({"pot1": dict(POT1, pot_id="pot-A")}, board="pico")
    cal.set_sections({"pot2": dict(POT2, pot_id="pot-B")})
    cal.set_sections({"df": DF_SECTION})
    force = poly_section([0.65, 12.37, 2.08], (-2.0, 6.0), 1000, 1000, ("um", "mN"))
    crc = cal.set_sections({"force": force})
    doc = read_calibration(path)
    assert doc["board"] == "pico" and doc["pots"] == {"pot1": "pot-A", "pot2": "pot-B"}
    assert [doc[name]["fixed"] for name in ("pot1", "pot2", "df", "force")] == [POT1["fixed"], POT2["fixed"], DF_SECTION["fixed"], force["fixed"]]
    assert crc == parse_document(path.read_text())[1]  # the CRC the board checks
    cal_fw = load_calibration(str(path))
    assert poly(2000, cal_fw.force) == round(1000 * (0.65 * 4 + 12.37 * 2 + 2.08))
    with pytest.raises(UserError, match="unknown calibration section"):
        cal.set_sections({"pot3": POT1})
    path.write_bytes(path.read_bytes().replace(b"pico", b"pica"))
    corrupt = path.read_bytes()
    with pytest.raises(UserError, match="CRC"):
        cal.set_sections({"force_inverse": force})
    assert path.read_bytes() == corrupt, "a corrupt file is reported, never silently replaced"


def test_new_pot_curves_leave_out_what_was_measured_through_the_old_ones(tmp_path):
    """The file owns the rule: new pot curves leave out the end stops (their frame of positions
    moved); new pots (a full calibration) also Df, the force model and the friction."""
    path = tmp_path / "cal.json"
    force = poly_section([0.65, 12.37, 2.08], (-2.0, 6.0), 1000, 1000, ("um", "mN"))
    full = {"pot1": POT1, "pot2": POT2, "df": DF_SECTION, "force": force, "stroke": stroke_section(0.1, 59.9)}
    cal = CalibrationFile(path)
    cal.set_sections(full)
    cal.set_sections({"pot1": POT1})  # a refit of the same pot
    assert cal.left_out == ["stroke"] and set(cal.read()) >= {"df", "force"} and "stroke" not in cal.read()
    cal.set_sections(full)
    cal.set_sections({"pot1": POT1, "pot2": POT2, "stroke": stroke_section(0.2, 59.8)}, new_pots=True)
    doc = cal.read()
    assert cal.left_out == ["df", "force"] and "df" not in doc and "force" not in doc
    assert doc["stroke"]["fixed"] == stroke_section(0.2, 59.8)["fixed"]  # measured with the new curves: kept
    cal.set_sections({"df": DF_SECTION})
    assert cal.left_out == [] and "df" in cal.read()  # no pot curve, nothing left out


def test_new_pots_replace_an_unreadable_file_only_once_it_is_kept_aside(tmp_path):
    """set_sections keeps the file as it was before it writes (whoever calls it); an unreadable
    file is refused unless new pot curves replace it, and then it is in the dated copy."""
    path = tmp_path / "cal.json"
    path.write_text("not a calibration")
    cal = CalibrationFile(path)
    with pytest.raises(UserError):
        cal.set_sections({"pot1": POT1})  # a section among the others: they cannot be read
    assert cal.backup.read_text() == "not a calibration" and cal.keep_previous() is None  # kept, once
    assert path.read_text() == "not a calibration"
    cal.set_sections({"pot1": POT1}, new_pots=True)
    assert cal.read()["pot1"]["fixed"] == POT1["fixed"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cal.json", cal.backup.name]


def test_every_write_keeps_the_file_as_it_was(tmp_path):
    """No caller has to remember the backup: the first write through a CalibrationFile keeps a
    dated copy of a file that was there, and a new file makes none."""
    path = tmp_path / "cal.json"
    CalibrationFile(path).set_sections({"pot1": POT1})
    assert [p.name for p in tmp_path.iterdir()] == ["cal.json"]
    before = path.read_bytes()
    cal = CalibrationFile(path)
    cal.set_sections({"pot2": POT1})
    assert cal.backup.read_bytes() == before and "pot2" in cal.read()


def test_firmware_loader_under_micropython(tmp_path):
    path = tmp_path / "cal.json"
    doc = full_document(board="pico \u00b5")
    doc["force_inverse"] = poly_section([0.00091, 0.070, -0.18], (-20.0, 80.0), 1000, 1000, ("mN", "um"))
    crc = write_calibration(path, doc)
    bad = tmp_path / "bad.json"
    text = path.read_bytes()
    i = text.index(b"fixed") + 12
    bad.write_bytes(text[:i] + bytes([text[i] ^ 0x04]) + text[i + 1 :])
    cal = load_calibration(str(path))
    codes = list(range(0, 4096, 5))
    source = (
        "from firmware.calibration import load_calibration, convert, CalibrationError\n"
        "from firmware.poly_fixed import poly\n"
        "c = load_calibration(%r)\n"
        "print(c.crc, c.version, c.board == %r, c.force is None)\n"
        "print(c.pot1[0], c.pot2[0], list(c.pot1[1]) == %r)\n"
        "print(' '.join([str(convert(c.pot1[0], x, c.pot1[1])) for x in %r]))\n"
        "print(' '.join([str(convert(c.pot2[0], x, c.pot2[1])) for x in %r]))\n"
        "print(poly(30000, c.df), poly(5000, c.force_inverse))\n"
        "for p in (%r, %r):\n"
        "    try:\n"
        "        load_calibration(p)\n"
        "        print('loaded')\n"
        "    except CalibrationError as e:\n"
        "        print('refused:', e)\n"
    ) % (str(path), "pico \u00b5", list(cal.pot1[1]), codes, codes, str(bad), str(tmp_path / "missing.json"))
    out = run_micropython(source).stdout.splitlines()
    assert out[0] == "%d 2 True True" % crc
    assert out[1] == "bcm3 pwl True"
    assert out[2].split() == [str(convert(cal.pot1[0], x, cal.pot1[1])) for x in codes]
    assert out[3].split() == [str(convert(cal.pot2[0], x, cal.pot2[1])) for x in codes]
    assert out[4] == "%d %d" % (poly(30000, cal.df), poly(5000, cal.force_inverse))
    assert out[5].startswith("refused:") and "CRC" in out[5]
    assert out[6].startswith("refused: no calibration file")
