"""host flash against the virtual board with real mpy-cross and mpremote: a blank board becomes a
working one (closed-loop move), and a flash killed at any moment leaves a bootable board with the
old or the new calibration, never a broken one."""

import os
import signal
import subprocess
import sys
import time

import pytest

from firmware.calibration import load_calibration
from host import cli
from host.board_client import BoardClient
from host.calibration_file import new_document, write_calibration
from host.flashing import flash
from host.virtual_board import VirtualBoard

import fake_hardware


def sim_calibration(path, date):
    """The simulated actuator's model calibration written as a calibration file (B's format)."""
    cal = fake_hardware.model_calibration()
    doc = new_document(board="sim", date=date)
    for name in ("pot1", "pot2"):
        doc[name] = {"kind": cal[name][0], "fixed": cal[name][1]}
    for name in ("df", "force", "force_inverse"):
        doc[name] = {"kind": "poly", "fixed": cal[name]}
    write_calibration(path, doc)
    return load_calibration(str(path)).crc


@pytest.fixture(scope="module")
def calibrations(tmp_path_factory):
    d = tmp_path_factory.mktemp("cal")
    a, b = d / "a.json", d / "b.json"
    return {"a": (a, sim_calibration(a, "2026-01-01")), "b": (b, sim_calibration(b, "2026-02-02"))}


@pytest.fixture(scope="module")
def flashed(calibrations):
    """A blank virtual board (empty flash), flashed once with calibration a."""
    with VirtualBoard(factory=False) as board:
        assert not any(board.root.iterdir())
        status = flash(board.path, "sim", str(calibrations["a"][0]), progress=lambda s: None)
        yield board, status


def test_flash_installs_compiled_firmware_and_verified_calibration(flashed, calibrations):
    board, status = flashed
    path, crc = calibrations["a"]
    assert status["calibration_crc"] == crc and status["calibration_error"] is None
    root = board.root
    assert (root / "calibration.json").read_bytes() == path.read_bytes()
    assert (root / "main.py").read_text().startswith("from firmware.board_main import run")
    mods = sorted(p.name for p in (root / "firmware").iterdir())
    assert "link.mpy" in mods and "app.mpy" in mods
    assert [m for m in mods if m.endswith(".py")] == ["__init__.py"]  # everything else compiled
    assert not (root / "_new").exists()


def test_closed_loop_move_on_the_flashed_board(flashed, capsys):
    board, _ = flashed
    assert cli.main(["move", "--port", board.path, "--to", "42", "--timeout", "20"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("reached at ")
    assert abs(float(out.split()[2]) - 42.0) <= 0.2  # the firmware's D2 settled on the target
    with BoardClient(board.path) as client:
        assert client.call("status")["mode"] == "idle"  # the move ends with the motor off


def test_flash_killed_at_many_points_leaves_old_or_new_calibration(flashed, calibrations):
    board, _ = flashed
    old_path, old_crc = calibrations["a"]
    new_path, new_crc = calibrations["b"]
    command = [sys.executable, "-m", "host", "flash", "--port", board.path, "--calibration", str(new_path)]
    start = time.monotonic()
    subprocess.run(command, check=True, capture_output=True)  # how long a whole flash takes here
    full = time.monotonic() - start
    flash(board.path, "sim", str(old_path), progress=lambda s: None)
    seen = set()
    for fraction in (0.15, 0.45, 0.7, 0.85, 0.95, 1.05):
        delay = fraction * full
        proc = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
        time.sleep(delay)
        os.killpg(proc.pid, signal.SIGKILL)  # the host process and its mpremote, mid-flight
        proc.wait()
        time.sleep(0.3)  # a swap already received by the board runs to its end
        on_board = (board.root / "calibration.json").read_bytes()
        assert on_board in (old_path.read_bytes(), new_path.read_bytes())
        with BoardClient(board.path, timeout=1.0) as client:  # it boots and answers
            crc = client.status_info["calibration_crc"]
        assert crc in (old_crc, new_crc)
        assert crc == (new_crc if on_board == new_path.read_bytes() else old_crc)
        seen.add(crc)
        # Put the old calibration back for the next round when the new one got through.
        if crc == new_crc:
            flash(board.path, "sim", str(old_path), progress=lambda s: None)
    print("kill outcomes:", {"old" if c == old_crc else "new" for c in seen})
    assert old_crc in seen  # some kills landed before the swap (the interesting case)
    assert new_crc in seen  # and some after it
