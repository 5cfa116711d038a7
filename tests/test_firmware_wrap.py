"""Forever-safe counters: the step runs across every counter's wrap or saturation point with
the heap locked, on CPython, on the MicroPython unix port and on the emulated Cortex-M0 with its
31-bit small ints (../shared/mcu/run-on-mcu, qemu-system-arm), where an overflow would show."""

import json
import os
import shutil
import subprocess
import sys

import pytest

import fake_hardware
import firmware_wrap_cases
from micropython_runner import REPO, run_case

RUN_ON_MCU = REPO.parent / "shared" / "mcu" / "run-on-mcu"


@pytest.fixture(scope="module")
def wrap_data(tmp_path_factory):
    board = fake_hardware.sim_board()
    data = {"codes": fake_hardware.record_codes(board, steps=60, duty=3000), "cal": fake_hardware.model_calibration(board)}
    path = tmp_path_factory.mktemp("wrap") / "data.json"
    path.write_text(json.dumps(data))
    return path


def test_counters_wrap_on_cpython_and_the_unix_port(wrap_data):
    here = firmware_wrap_cases.case_counters_wrap(str(wrap_data))
    there = run_case("firmware_wrap_cases", "case_counters_wrap(%r)" % str(wrap_data))
    assert here == there
    assert there["overruns"] == firmware_wrap_cases.MASK


def _mcu_or_skip():
    why = None
    if not RUN_ON_MCU.exists():
        why = "../shared/mcu/run-on-mcu is absent (the emulated chips live beside the checkout)"
    elif shutil.which("qemu-system-arm") is None:
        why = "qemu-system-arm is not installed (apt-get install qemu-system-arm; .ci/run does)"
    if why:
        if os.environ.get("CI") == "true":
            pytest.fail("CI must run the emulated-M0 test: " + why)
        pytest.skip(why)


def test_counters_wrap_on_the_emulated_m0(wrap_data, tmp_path):
    """The firmware as mpy-cross -march=armv6m files, the same case, 31-bit small ints."""
    _mcu_or_skip()
    from host.link.flashing import mpy_cross_executable

    rom = tmp_path / "rom"
    (rom / "firmware").mkdir(parents=True)
    for src in sorted((REPO / "firmware").glob("*.py")):
        subprocess.run([mpy_cross_executable(), "-march=armv6m", "-o", str(rom / "firmware" / (src.stem + ".mpy")), str(src)], check=True)
    for name in ("firmware_cases.py", "fake_hardware.py", "firmware_wrap_cases.py"):
        shutil.copy(REPO / "tests" / name, rom / name)
    shutil.copy(REPO / "boards" / "sim.json", rom / "sim.json")
    shutil.copy(wrap_data, rom / "data.json")
    script = tmp_path / "wrap.py"
    script.write_text(
        "import json, firmware_wrap_cases as w\n"
        "print('RESULT ' + json.dumps(w.case_counters_wrap('/rom/data.json', board_path='/rom/sim.json')))\n"
    )
    proc = subprocess.run(
        [sys.executable, str(RUN_ON_MCU), "--cpu", "m0", "--files", str(rom), "--timeout", "300", str(script)],
        capture_output=True, text=True, timeout=400,
    )
    lines = [l for l in proc.stdout.splitlines() if l.startswith("RESULT ")]
    assert proc.returncode == 0 and lines, proc.stdout[-3000:] + proc.stderr[-3000:]
    got = json.loads(lines[-1][len("RESULT "):])
    assert got == firmware_wrap_cases.case_counters_wrap(str(wrap_data))
