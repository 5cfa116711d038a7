"""A telemetry log says what its numbers are: RUN.meta.json beside RUN.csv (board, firmware,
calibration CRC, loop period, rate, date, each column's unit, the mode and fault code tables)."""

import json

from firmware.protocol import FIELDS, MODES, VERSION
from firmware.protocol import FAULT_NAMES
import host
from host import cli
from host.link.telemetry_log import MEANING, UNITS, load

from testkit.model import write_model_calibration


def test_every_column_has_a_unit():
    from firmware.protocol import FIELD_UNITS

    assert len(FIELD_UNITS) == len(FIELDS)  # the interface table's units, one per field
    assert set(MEANING) == set(FIELDS) and set(UNITS) == set(FIELDS)


def test_every_status_key_has_its_label_in_host_status():
    from firmware.protocol import STATUS_KEYS
    from host.commands.status import LABELS

    assert set(LABELS) == set(STATUS_KEYS)


def test_host_log_writes_the_metadata_beside_the_csv(tmp_path, capsys):
    cal = tmp_path / "cal.json"
    write_model_calibration(cal, date="2026-03-03")
    out = tmp_path / "run.csv"
    assert cli.main(["log", "--port", "sim", "--calibration", str(cal), "--seconds", "0.5", "--rate", "200",
                     "--out", str(out)]) == 0
    assert "run.meta.json" in capsys.readouterr().out
    meta = json.loads((tmp_path / "run.meta.json").read_text())
    assert meta["board"] == "sim" and meta["stream_hz"] == 200 and meta["loop_period_us"] == 1000 and meta["loop_hz"] == 1000
    assert meta["calibration_crc"] == "%08x" % json.loads(cal.read_text())["crc32"]
    assert meta["firmware"] == VERSION and meta["host"] == host.__version__
    assert list(meta["columns"]) == list(FIELDS) and meta["date"].endswith("+00:00")
    assert meta["modes"] == {str(i): n for i, n in enumerate(MODES)}
    assert meta["faults"] == {str(b): n for b, n in FAULT_NAMES}
    data = load(out)  # the CSV itself stays a plain table
    assert len(data["t_us"]) >= 50 and set(data["mode"]) <= {int(k) for k in meta["modes"]}


def test_host_log_onto_an_existing_file_keeps_it_under_a_dated_name(tmp_path, capsys):
    """`host log --out cal.json` by a slip of the hand: the calibration must survive (a dated
    copy beside it, as fit and calibrate keep one), and the command says where it went."""
    cal = tmp_path / "cal.json"
    write_model_calibration(cal, date="2026-03-03")
    before = cal.read_bytes()
    assert cli.main(["log", "--port", "sim", "--calibration", str(cal), "--seconds", "0.2", "--out", str(cal)]) == 0
    kept = list(tmp_path.glob("cal.json.*.bak"))
    assert len(kept) == 1 and kept[0].read_bytes() == before
    assert cal.read_text().startswith(",".join(FIELDS))  # the log went where it was asked to
    assert kept[0].name in capsys.readouterr().err
