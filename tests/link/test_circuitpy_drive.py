"""`host flash --drive`: the firmware onto a mounted CIRCUITPY drive (host/link/circuitpy_drive.py),
here a directory standing in for the drive: what lands where, verified, the old calibration kept
until the new one is in place, and the refusals, each one line, before anything is written."""

import json

import pytest

from host import cli
from host.link.plain_firmware import EMITTERS
from testkit.model import sim_board, write_model_calibration


@pytest.fixture
def drive(tmp_path):
    root = tmp_path / "CIRCUITPY"
    root.mkdir()
    (root / "boot_out.txt").write_text("Adafruit CircuitPython 10.2.1 on 2026-11-26; Raspberry Pi Pico with rp2040\n")
    (root / "code.py").write_text("print('Hello World!')\n")  # what CircuitPython puts on a new drive
    return root


def calibration(tmp_path, name):
    path = tmp_path / name
    write_model_calibration(path, board=dict(sim_board(), name="pico_circuitpython"))
    return path


def test_the_plain_firmware_code_py_board_and_calibration_land_on_the_drive(drive, tmp_path, capsys):
    cal = calibration(tmp_path, "a.json")
    assert cli.main(["flash", "--drive", str(drive), "--board", "pico_circuitpython", "--calibration", str(cal)]) == 0
    assert "verified" in capsys.readouterr().out
    assert (drive / "code.py").read_text().startswith("from firmware.board_main import run")
    assert json.loads((drive / "board.json").read_text())["runtime"] == "circuitpython"
    assert (drive / "calibration.json").read_bytes() == cal.read_bytes()
    step = (drive / "firmware" / "controller.py").read_text()
    assert "def _step" in step and not any(line.strip() in EMITTERS for line in step.splitlines())
    assert not list(drive.rglob("*.new")) and not list(drive.rglob("*.old"))


def test_a_new_calibration_replaces_the_old_one(drive, tmp_path):
    first, second = calibration(tmp_path, "a.json"), tmp_path / "b.json"
    write_model_calibration(second, board=dict(sim_board(), name="pico_circuitpython"), pots="bcm3")
    for cal in (first, second):
        assert cli.main(["flash", "--drive", str(drive), "--board", "pico_circuitpython", "--calibration", str(cal)]) == 0
    assert (drive / "calibration.json").read_bytes() == second.read_bytes()


def test_refusals_are_one_line_and_write_nothing(drive, tmp_path, capsys):
    before = sorted(p.name for p in drive.rglob("*"))
    cases = [
        (["--drive", str(tmp_path), "--board", "pico_circuitpython"], "not a CircuitPython drive"),
        (["--drive", str(drive), "--board", "pico"], "not for CircuitPython"),
        (["--drive", str(drive)], "--drive needs --board"),
        (["--drive", str(drive), "--board", "pico_circuitpython", "--calibration", str(tmp_path / "none.json")],
         "calibration file not found"),
    ]
    for args, said in cases:
        assert cli.main(["flash"] + args) == 2
        err = capsys.readouterr().err.strip()
        assert said in err and len(err.splitlines()) == 1, err
    assert sorted(p.name for p in drive.rglob("*")) == before


def test_a_file_the_drive_does_not_hold_as_written_fails_the_install(drive, monkeypatch, capsys):
    """The read-back: a drive that kept other bytes than were written (a flaky card, a full
    drive that truncated) is caught by the CRC comparison."""
    import host.link.circuitpy_drive as circuitpy_drive

    put = circuitpy_drive._put

    def truncating(data, path):
        crc = put(data, path)
        if path.name == "board.json":
            path.write_bytes(data[:-5])
        return crc

    monkeypatch.setattr(circuitpy_drive, "_put", truncating)
    assert cli.main(["flash", "--drive", str(drive), "--board", "pico_circuitpython"]) == 2
    err = capsys.readouterr().err
    assert "verification failed: board.json" in err, err
