"""The firmware on an emulated Raspberry Pi Pico running CircuitPython (10.2.1 for raspberry_pi_pico,
from ../shared/mcu/rp2/circuitpython) on rp2040js, the simulated actuator on the pins of
boards/pico_circuitpython.json: installed by `host flash` over the emulated USB serial (plain
source, host/link/plain_firmware.py, through the raw REPL), then `host status`, a closed-loop move
and a force hold against the plant, with the step paced by the main loop (no timer interrupt).

Without ../shared these skip with the reason; under CI (CI=true) that is a failure.
"""

import json

import pytest

from testkit.interpreters import REPO
from testkit.processes import run as host
from testkit.model import sim_board, write_model_calibration
from tests.conftest import SHARED, shared_dir
from tests.link.emulated_moves import move_and_hold

UF2 = SHARED / "mcu" / "rp2" / "circuitpython" / "circuitpython-10.2.1-raspberry_pi_pico.uf2"
BOARD = "pico_circuitpython"




@pytest.fixture(scope="module")
def calibration(tmp_path_factory):
    """The simulated actuator's own calibration (pot tables, Df, force, friction), made for this board."""
    path = tmp_path_factory.mktemp("cal") / "pico-cp-model.json"
    crc = write_model_calibration(path, board=dict(sim_board(), name=BOARD))
    return path, crc


@pytest.fixture(scope="module")
def pico(calibration):
    """An emulated Pico with CircuitPython out of its box (it formats its own drive), then `host flash`."""
    shared_dir(UF2.parent, "CircuitPython for the emulated Pico")
    from host.link.emulated_pico.board import EmulatedPico

    with EmulatedPico(uf2=str(UF2)) as board:
        assert board.runtime == "circuitpython" and board.board_path.name == BOARD + ".json"
        # a board file for MicroPython is refused in one line, before anything is copied
        code, out, err = host("flash", "--port", board.path, "--board", "pico")
        assert code == 2 and "runs CircuitPython" in err and BOARD in err, out + err
        code, out, err = host("flash", "--port", board.path, "--board", BOARD, "--calibration", str(calibration[0]))
        assert code == 0, out + err
        assert "flashed: firmware" in out and "on " + BOARD in out, out
        yield board


def test_host_status_on_the_flashed_circuitpython_pico(pico, calibration):
    code, out, err = host("status", "--port", pico.path, "--json")
    assert code == 0, err
    status = json.loads(out)
    assert status["board"] == BOARD
    assert status["interpreter"].startswith("circuitpython 10.")  # told apart by what the board says
    assert status["timer"] == "paced"  # no timer interrupt: the main loop runs the step
    assert status["period_us"] == 1000000 // json.loads((REPO / "boards" / (BOARD + ".json")).read_text())["loop_hz"]
    assert status["faults"] == []
    assert status["calibration_crc"] == "%08x" % calibration[1] and status["calibration_error"] is None


def test_a_move_and_a_force_hold_against_the_plant(pico):
    # the estimate settles first; the block follows the spring within the next periods (at 250 Hz a
    # quarter as many a second as at 1 kHz): half a second of board time before the gauge is read
    move_and_hold(pico, timeout_s=60, settle_s=0.5, rate=250)


def test_saved_parameters_and_the_exit_cause_survive_a_restart_in_nvm(pico):
    """CircuitPython's drive is read-only to code: `host params --save` keeps the values in the
    chip's microcontroller.nvm (firmware/records.py), the next boot loads them, and the cause of
    the run the restart ended (Ctrl-C) is read back from there."""
    from firmware.protocol import PARAMS
    from host.link.board_client import BoardClient

    default = dict((row[0], row[1]) for row in PARAMS)["kp_pos"]
    code, out, err = host("params", "--port", pico.path, "kp_pos=%d" % (default + 32), "--save")
    assert code == 0 and "nvm:params.txt" in out, out + err
    try:
        with BoardClient(pico.path, check=False) as client:
            assert client.soft_reset(wait=60)
        code, out, err = host("status", "--port", pico.path, "--json")
        assert code == 0, err
        status = json.loads(out)
        assert status["params_saved"] == {"kp_pos": default + 32}, status
        assert status["params_file_error"] is None
        assert status["last_exit"].startswith("interrupted: KeyboardInterrupt"), status["last_exit"]
    finally:  # the defaults again, saved, for whatever runs on this board next
        code, out, err = host("params", "--port", pico.path, "kp_pos=%d" % default, "--save")
        assert code == 0, out + err
