"""A board that steps slower than 1 kHz (CircuitPython's 250 Hz) gets the per-step constants the
same per second: the integral gains and the force setpoint's ramp scaled up from the table's
(within each parameter's limit), the spring force's low-pass over the same 64 ms; at 1 kHz and
above they are the table's."""

import json

from boards.sim.machine import for_board
from firmware.app import App
from firmware.param_table import PER_STEP_PARAMS
from firmware.calibration import load_calibration
from firmware.measurement import FS_SHIFT
from firmware.protocol import PARAMS
from testkit.model import sim_board, write_model_calibration


def app_at(tmp_path, loop_hz):
    board = dict(sim_board(), loop_hz=loop_hz)
    path = tmp_path / ("sim%d.json" % loop_hz)
    path.write_text(json.dumps(board))
    cal = tmp_path / "cal.json"
    write_model_calibration(cal)
    app = App(str(path), None, machine=for_board(str(path)))
    app.set_calibration(load_calibration(str(cal)))
    return app


def test_per_step_constants_follow_the_loop_rate(tmp_path):
    table = {row[0]: row for row in PARAMS}
    fast, slow, faster = app_at(tmp_path, 1000), app_at(tmp_path, 250), app_at(tmp_path, 2000)
    for name in PER_STEP_PARAMS:
        i = [row[0] for row in PARAMS].index(name)
        assert fast.ctrl.p[i] == faster.ctrl.p[i] == table[name][1]
        assert slow.ctrl.p[i] == min(table[name][3], 4 * table[name][1]), name
    assert slow.ctrl.p[[row[0] for row in PARAMS].index("kp_force")] == table["kp_force"][1]  # a P gain is per um
    assert (fast.ctrl.meas.st[FS_SHIFT], slow.ctrl.meas.st[FS_SHIFT], faster.ctrl.meas.st[FS_SHIFT]) == (6, 4, 6)
    for app in (fast, slow, faster):
        app.shutdown()
