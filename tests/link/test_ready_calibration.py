"""The simulated actuator's shipped calibration (boards/sim/calibration.json, made by
boards/make_sim_calibration.py with the project's own guided calibration): a virtual board of
boards/sim.json starts with it, so `host move --port sim` works at once, and it still describes
the model (if this file fails after a change to the model, the calibration or the file format,
run boards/make_sim_calibration.py)."""

import json

import numpy as np

from firmware.calibration import load_calibration
from host import cli
from host.calibration.file import read_calibration
from host.calibration.report import _poly_inputs, evaluate, pot_positions_um
from host.link.virtual_board import READY_CALIBRATION
from testkit import interpreters, model

CASES = "tests.sim.force_cases"


def test_the_shipped_calibration_still_matches_the_model():
    doc = read_calibration(READY_CALIBRATION)  # CRC and layout, as the host reads it
    assert doc["board"] == "sim" and load_calibration(str(READY_CALIBRATION)) is not None  # and as the board does
    exact = model.model_sections()
    for pot in ("pot1", "pot2"):
        shipped, true = pot_positions_um(doc[pot], pot), pot_positions_um(exact[pot], pot)
        inside = (true > true.min() + 1) & (true < true.max() - 1)  # where the model's table is not clamped
        assert np.abs(shipped[inside] - true[inside]).max() <= 100, pot  # um, over the whole stroke
    k, _ = _poly_inputs(doc["df"], "df")
    k_true, _ = _poly_inputs(exact["df"], "df")
    for d1 in range(6000, 55000, 4000):  # inside both sections' D1 ranges
        assert abs(evaluate(doc["df"], k, d1, "df") - evaluate(exact["df"], k_true, d1, "df")) <= 50, d1
    # the force sections in use: the paper's steps against the gauge (what it reads, tared), both sides
    for side, sign in (("high", -1), ("low", 1)):
        rows = interpreters.on_cpython(CASES, "case_force_steps_sim(%r, %r, %r, measured=True)" % (
            str(READY_CALIBRATION), side, [sign * t for t in (5000, 10000, 15000, 10000, 5000)]))
        worst = max(abs(load - target) / abs(target) for target, _, load in rows)
        assert worst <= 0.03, (side, rows)


def test_a_virtual_board_starts_calibrated_unless_asked_not_to(capsys):
    assert cli.main(["move", "--port", "sim", "--to", "20"]) == 0  # no host calibrate first
    capsys.readouterr()
    assert cli.main(["status", "--port", "sim", "--json"]) == 0
    crc = json.loads(capsys.readouterr().out)["calibration_crc"]
    assert len(crc) == 8 and int(crc, 16) >= 0  # hex, as flash, show and the log's metadata write it
    assert cli.main(["status", "--port", "sim", "--uncalibrated", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["calibration_crc"] is None
