"""`host flash --drive` onto a real CIRCUITPY FAT volume, read back by CircuitPython itself.

The emulated CircuitPython Pico (../shared/mcu/rp2/circuitpython) formats its own drive at its
first boot; with the board stopped, that part of its flash is mounted as a directory through
FUSE (testkit/fat_drive.py: pyfatfs, long file names, case-insensitive as a computer's FAT
driver), `host flash --drive` copies the firmware and a calibration onto it as onto a drive a
computer has mounted, and the board starts again from that flash: CircuitPython's own FAT code
reads code.py, the firmware and the calibration. rp2040js has no USB mass storage, so the board
is stopped while the drive is mounted, as if it were unplugged, copied to and plugged back.

Without ../shared or FUSE these skip with the reason; under CI (CI=true) that is a failure
(.ci/run installs fuse).
"""

import json
import os

import pytest

from testkit import fat_drive
from testkit.processes import run as host
from testkit.model import sim_board, write_model_calibration
from tests.conftest import SHARED, shared_dir
from tests.link.emulated_moves import move_and_hold

UF2 = SHARED / "mcu" / "rp2" / "circuitpython" / "circuitpython-10.2.1-raspberry_pi_pico.uf2"
BOARD = "pico_circuitpython"




def formatted_within(image, offset, seconds, quiet_s=3.0):
    """Wait until the flash image holds a FAT boot sector at `offset` and has not changed for
    `quiet_s` (CircuitPython formats its drive at its first boot, then writes boot_out.txt; the
    image is written through on every flash write)."""
    import time

    deadline = time.monotonic() + seconds
    last, since = None, time.monotonic()
    while True:
        now, data = time.monotonic(), image.read_bytes()
        if data != last:
            last, since = data, now
        elif data[offset:offset + 1] in (b"\xeb", b"\xe9") and now - since >= quiet_s:  # a FAT boot sector's jump
            return
        assert now < deadline, "CircuitPython did not format its drive and settle within %.0f s" % seconds
        time.sleep(0.5)


def status_after_boot(pico, tries=20):
    """`host status --json` once the firmware answers (CircuitPython compiles it at boot)."""
    for _ in range(tries):
        code, out, err = host("status", "--port", pico.path, "--json")
        if code == 0:
            return json.loads(out)
    raise AssertionError("no firmware answered after the drive was written: " + err)


@pytest.fixture(scope="module")
def tools():
    shared_dir(UF2.parent, "CircuitPython for the emulated Pico")
    why = fat_drive.available()
    if why:
        if os.environ.get("CI", "").strip().lower() == "true":
            pytest.fail("CI must mount the CIRCUITPY drive: " + why)
        pytest.skip(why)
    from host.link.emulated_pico.board import CIRCUITPY_NVM_BYTES, EmulatedPico

    return EmulatedPico, CIRCUITPY_NVM_BYTES


def test_host_flash_drive_onto_circuitpythons_own_fat_then_the_board_runs_it(tools, tmp_path):
    EmulatedPico, nvm_bytes = tools
    image = tmp_path / "flash.img"
    first, second = tmp_path / "first.json", tmp_path / "second.json"
    crc_first = write_model_calibration(first, board=dict(sim_board(), name=BOARD))
    crc_second = write_model_calibration(second, board=dict(sim_board(), name=BOARD), pots="bcm3")
    with EmulatedPico(uf2=str(UF2), flash_image=str(image)) as pico:
        # out of its box: CircuitPython formats the drive and writes boot_out.txt; no firmware of ours
        code, out, err = host("status", "--port", pico.path)
        assert code != 0 and "no lsea-kit firmware" in err, out + err
        # the board is unplugged only once its drive is formatted and written, as a person waits
        # for CIRCUITPY to appear: that can end seconds after the status above has given up (2 s
        # later on 2026-11-27; stopping it sooner left the flash blank, "not a FAT partition")
        formatted_within(image, nvm_bytes, 60.0)

    drive = dict(offset=nvm_bytes, size=1024 * 1024)  # the FAT volume after the nvm sector
    with fat_drive.mounted(image, **drive) as mounted:
        names = os.listdir(mounted)
        assert "BOOT_OUT.TXT" in names and "board.json" not in names, names  # CircuitPython's short names
        code, out, err = host("flash", "--drive", mounted, "--board", BOARD, "--calibration", str(first))
        assert code == 0 and "verified" in out, out + err
    with EmulatedPico(uf2=str(UF2), flash_image=str(image)) as pico:
        status = status_after_boot(pico)
        assert status["interpreter"].startswith("circuitpython 10.") and status["board"] == BOARD, status
        assert status["calibration_crc"] == "%08x" % crc_first and status["calibration_error"] is None, status
        move_and_hold(pico, timeout_s=60, settle_s=0.5, rate=250)

    # a new calibration over the old one: replaced on the FAT, the old one gone, no .new left
    with fat_drive.mounted(image, **drive) as mounted:
        code, out, err = host("flash", "--drive", mounted, "--board", BOARD, "--calibration", str(second))
        assert code == 0, out + err
        names = os.listdir(mounted)
        assert not [n for n in names if n.endswith((".new", ".old"))], names
    with EmulatedPico(uf2=str(UF2), flash_image=str(image)) as pico:
        status = status_after_boot(pico)
        assert status["calibration_crc"] == "%08x" % crc_second and status["calibration_error"] is None, status
