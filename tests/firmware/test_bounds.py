"""Instrumented proof that the control step keeps every integer intermediate within +-2**30.

The unix port's small ints are 62-bit, so heap_lock cannot catch leaving the 31-bit range of a
32-bit board. Here (CPython) every firmware module is re-imported with each arithmetic operation
(binary, augmented, unary) rewritten to pass its result through a recorder, the firmware then
runs on the simulated actuator in every mode with the most demanding parameters, and the largest
magnitude seen is asserted. The bound analysis itself is in docs/firmware.md.
"""

import ast
import builtins
import importlib.abc
import importlib.machinery
import sys

import pytest

from testkit import model
from tests.sim import firmware_cases as sim_cases

LIMIT = 2**30
PEAK = {"value": 0, "where": None, "on": False}


def _chk_(value, where):
    if PEAK["on"] and type(value) is int and abs(value) > PEAK["value"]:
        PEAK["value"] = abs(value)
        PEAK["where"] = where
    return value


class _Instrument(ast.NodeTransformer):
    def __init__(self, module):
        self.module = module

    def _wrap(self, node, value):
        where = ast.Constant("%s:%d" % (self.module, node.lineno))
        return ast.Call(func=ast.Name("_chk_", ast.Load()), args=[value, where], keywords=[])

    def visit_BinOp(self, node):
        self.generic_visit(node)
        return ast.copy_location(self._wrap(node, node), node)

    def visit_UnaryOp(self, node):
        self.generic_visit(node)
        if isinstance(node.op, ast.USub):
            return ast.copy_location(self._wrap(node, node), node)
        return node

    def visit_AugAssign(self, node):
        self.generic_visit(node)
        load = ast.parse(ast.unparse(node.target), mode="eval").body  # same target, Load context
        value = ast.BinOp(left=load, op=node.op, right=node.value)
        return ast.copy_location(ast.Assign(targets=[node.target], value=self._wrap(node, value)), node)


class _Loader(importlib.machinery.SourceFileLoader):
    def get_code(self, fullname):
        tree = _Instrument(fullname).visit(ast.parse(self.get_data(self.path), self.path))
        return compile(ast.fix_missing_locations(tree), self.path, "exec")


class _Finder(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        # firmware.portable is the CPython stand-in (its clock is the host's), not board code;
        # firmware.calibration reads and checks the file at boot only and is released after it
        # (app.py): its CRC is a 32-bit unsigned value, a long int on a board, made once
        if name.startswith("firmware.") and name not in ("firmware.portable", "firmware.calibration"):
            spec = importlib.machinery.PathFinder.find_spec(name, path)
            if spec is not None:
                spec.loader = _Loader(name, spec.origin)
            return spec
        return None


@pytest.fixture
def instrumented():
    import host.calibration.fixed_export  # noqa: F401  (host code keeps the plain firmware modules it imports)

    saved = {k: v for k, v in sys.modules.items() if k == "firmware" or k.startswith("firmware.")}
    before = set(sys.modules)
    for k in saved:
        del sys.modules[k]
    finder = _Finder()
    sys.meta_path.insert(0, finder)
    builtins._chk_ = _chk_
    try:
        import firmware.app  # noqa: F401  (instrumented from here on)

        yield
    finally:
        sys.meta_path.remove(finder)
        del builtins._chk_
        # every module first imported while instrumented (firmware's, and any that bound its
        # names, e.g. boards.sim.machine) goes, so that later tests import plain ones again
        for k in [k for k in sys.modules if k == "firmware" or k.startswith("firmware.") or k not in before]:
            del sys.modules[k]
        sys.modules.update(saved)
        PEAK["on"] = False


def _extreme_params(app):
    from firmware.protocol import PARAMS

    for name, _, _lo, hi, _ in PARAMS:
        if name.startswith(("kp_", "ki_", "out_limit", "int_limit", "slew")):
            app.set_param(name, hi)


def test_step_intermediates_stay_within_31_bits(instrumented, tmp_path):
    from firmware.app import App

    import boards.sim.machine as sim

    from firmware.calibration import FRICTION_MAX_MN

    path = tmp_path / "cal.json"  # with the largest block friction a file may declare
    model.write_model_calibration(path, friction={"kind": "friction", "fixed": [FRICTION_MAX_MN]})
    PEAK.update(value=0, where=None, on=True)
    # position mode with the shipped gains, across the stroke
    sim_cases.case_position_sim(str(path), [10000, 58000, 2000], settle_ticks=800, hold_ticks=50)
    shipped = PEAK["value"]
    # every mode with every gain and limit at its maximum, driven into both stroke ends,
    # force targets at both extremes of the accepted range
    app = App("boards/sim.json", None, machine=sim.for_board("boards/sim.json"))
    app.set_calibration(sim_cases.load_calibration(str(path)))
    _extreme_params(app)
    app.set_param("host_timeout_ms", 600000)
    app.set_stream(1000)
    app.start()
    for mode, targets in (
        ("open_loop", [10000, -10000]),
        ("position", [65535, -65535, 30000]),
        ("force", [200000, -200000, 0]),
    ):
        app.set_mode(mode)
        for t in targets:
            app.set_target(t)
            sim.run_ticks(700)
    sim.world().set_load("gauge")
    app.set_mode("force")
    for t in (-15000, -200000):
        app.set_target(t)
        sim.run_ticks(700)
    app.shutdown()
    assert app.status()["faults"] == [], app.status()
    # the recorder really ran over the firmware's arithmetic
    assert shipped > 2**16 and PEAK["where"] is not None
    print("peak intermediate", PEAK)
    assert PEAK["value"] <= LIMIT, PEAK
