"""Scenarios of the simulated actuator: program text run under CPython and the real MicroPython
unix port (testkit.interpreters.programs), with the board, its physics parameters and `emit` in
scope. `run_both(body)` asserts that both printed exactly the same results (floats bit for bit)
and returns them; `run_each(body)` returns both, for scenarios timed by the wall clock.
"""

from testkit.interpreters import REPO, programs  # noqa: F401  (REPO: for the scenarios' tests)

PRELUDE = """
import json
from boards.sim.actuator import Actuator
import boards.sim.machine as machine
from testkit.exact import emit
BOARD = json.load(open('boards/sim.json'))
PARAMS = BOARD['actuator']
"""


def run_both(body):
    """Run the scenario on both interpreters; assert identical results; return them."""
    cpy, mpy = programs(PRELUDE + body)
    assert cpy == mpy, "CPython and MicroPython disagree:\n%s\n%s" % (cpy, mpy)
    return cpy


def run_each(body):
    """Run the scenario on both interpreters (wall-clock cases differ); return both."""
    return programs(PRELUDE + body)
