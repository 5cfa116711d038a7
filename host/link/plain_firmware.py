"""The firmware as plain bytecode: the same source with its code-emitter decorators taken out.

MicroPython compiles a function under `@micropython.viper` or `@micropython.native` to machine
code; CircuitPython has neither emitter (its compiler refuses the decorators), and a MicroPython
build may leave them out. The firmware is written so that the same functions run as bytecode
(docs/firmware.md, "The plain path"): this module makes that source by blanking the decorator
lines, so line numbers in a traceback still match the repository's files, and by taking out the
viper casts, which as bytecode return their argument. tests/firmware/test_plain_path.py checks
that the results are the same, bit for bit.
"""

import re
from pathlib import Path

FIRMWARE = Path(__file__).resolve().parents[2] / "firmware"
EMITTERS = ("@micropython.viper", "@micropython.native")


# A viper cast of a plain name, e.g. `ptr32(self.st)`: as bytecode on MicroPython and CircuitPython
# portable.ptr32 hands back its argument, so the call is taken out (a call costs about 10 us of a
# CircuitPython Pico's time, and the step makes 15 of them); `def ptr32(` is not a cast
_CAST = re.compile(r"(?<!def )\bptr(?:32|16)\(([A-Za-z_][\w.]*)\)")


def plain_source(text):
    """`text` (a firmware module's source) with every emitter decorator line left blank and
    every viper cast of a plain name replaced by the name."""
    lines = ("\n" if line.strip() in EMITTERS else line for line in text.splitlines(keepends=True))
    return _CAST.sub(r"\1", "".join(lines))


def write_plain_package(out_dir):
    """firmware/*.py as plain source in out_dir/firmware/; returns that directory."""
    dest = Path(out_dir) / "firmware"
    dest.mkdir(parents=True, exist_ok=True)
    for src in sorted(FIRMWARE.glob("*.py")):
        (dest / src.name).write_text(plain_source(src.read_text()))
    return dest
