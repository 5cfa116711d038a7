"""Helpers shared by the simulated-actuator tests (this module holds no tests).

`run_both(body)` runs one scenario (program text) under CPython and under the real MicroPython
unix port, checks that both printed exactly the same results (floats compared bit for bit as the
hex of their IEEE 754 doubles), and returns the decoded results for the test's assertions.
"""

import json
import struct
import subprocess
import sys

from micropython_runner import REPO, run_micropython

PRELUDE = """
import json, struct, binascii
from boards.sim.actuator import Actuator
import boards.sim.machine as machine
BOARD = json.load(open('boards/sim.json'))
PARAMS = BOARD['actuator']
def enc(v):
    if isinstance(v, float):
        return 'f' + binascii.hexlify(struct.pack('<d', v)).decode()
    if isinstance(v, (list, tuple)):
        return [enc(x) for x in v]
    if isinstance(v, dict):
        return dict((k, enc(x)) for k, x in v.items())
    return v
def emit(d):
    print('RESULT ' + json.dumps(enc(d)))
"""


def _dec(v):
    if isinstance(v, str) and v.startswith("f") and len(v) == 17:
        return struct.unpack("<d", bytes.fromhex(v[1:]))[0]
    if isinstance(v, list):
        return [_dec(x) for x in v]
    if isinstance(v, dict):
        return {k: _dec(x) for k, x in v.items()}
    return v


def _result(stdout):
    lines = [ln for ln in stdout.splitlines() if ln.startswith("RESULT ")]
    assert len(lines) == 1, stdout
    return json.loads(lines[0][len("RESULT "):])


def run_cpython(body):
    src = PRELUDE + body
    proc = subprocess.run([sys.executable, "-c", src], cwd=str(REPO), capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    return _result(proc.stdout)


def run_both(body):
    """Run the scenario on both interpreters; assert identical results; return them decoded."""
    cpy = run_cpython(body)
    mpy = _result(run_micropython(PRELUDE + body).stdout)
    assert cpy == mpy, "CPython and MicroPython disagree:\n%s\n%s" % (cpy, mpy)
    return _dec(cpy)


def run_each(body):
    """Run the scenario on both interpreters (wall-clock cases differ); return both, decoded."""
    cpy = run_cpython(body)
    mpy = _result(run_micropython(PRELUDE + body).stdout)
    return _dec(cpy), _dec(mpy)
