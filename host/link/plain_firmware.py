"""The firmware as plain bytecode: the same source with its code-emitter decorators taken out.

MicroPython compiles a function under `@micropython.viper` or `@micropython.native` to machine
code; CircuitPython has neither emitter (its compiler refuses the decorators), and a MicroPython
build may leave them out. The firmware is written so that the same functions run as bytecode
(docs/firmware.md, "The plain path"): this module makes that source by blanking the decorator
lines, so line numbers in a traceback still match the repository's files. Nothing else changes,
and tests/firmware/test_plain_path.py checks the results are the same, bit for bit.
"""

from pathlib import Path

FIRMWARE = Path(__file__).resolve().parents[2] / "firmware"
EMITTERS = ("@micropython.viper", "@micropython.native")


def plain_source(text):
    """`text` (a firmware module's source) with every emitter decorator line left blank."""
    return "".join("\n" if line.strip() in EMITTERS else line for line in text.splitlines(keepends=True))


def write_plain_package(out_dir):
    """firmware/*.py as plain source in out_dir/firmware/; returns that directory."""
    dest = Path(out_dir) / "firmware"
    dest.mkdir(parents=True, exist_ok=True)
    for src in sorted(FIRMWARE.glob("*.py")):
        (dest / src.name).write_text(plain_source(src.read_text()))
    return dest
