"""Step-response figures (host/fitting/step_response.py) on responses with known answers, and `host tune`
on the virtual board: the default gains settle, a gain set that oscillates is reported as such,
a grid recommends a settling set, the plot is written and the board's gains are put back."""

import json

import numpy as np
import pytest

from host import cli
from host.fitting.step_response import analyse, best
from host.link.virtual_board import VirtualBoard
from host.link.board_client import BoardClient



def second_order(zeta, wn, t):
    """Unit step response of a standard second-order system (zeta < 1)."""
    wd = wn * np.sqrt(1 - zeta**2)
    return 1 - np.exp(-zeta * wn * t) * (np.cos(wd * t) + zeta / np.sqrt(1 - zeta**2) * np.sin(wd * t))


def test_figures_of_a_second_order_response_match_the_textbook():
    t = np.arange(0, 3.0, 0.001)
    zeta, wn = 0.3, 20.0
    r = analyse(t, 10 + 5 * second_order(zeta, wn, t), 10, 15, band=0.1)  # 2 % band
    assert r.overshoot == pytest.approx(np.exp(-np.pi * zeta / np.sqrt(1 - zeta**2)), rel=0.01)  # 37 %
    assert r.settling_s == pytest.approx(4 / (zeta * wn), rel=0.25)  # the 2 % rule of thumb
    assert 0.05 < r.rise_s < 0.1 and abs(r.steady_error) < 0.01 and r.settled and r.verdict() == "settles"


def test_a_limit_cycle_is_oscillating_and_noise_is_not():
    t = np.arange(0, 2.0, 0.001)
    rng = np.random.default_rng(1)
    cycle = 5 + 0.3 * np.sin(2 * np.pi * 6 * t) + rng.normal(0, 0.02, len(t))
    r = analyse(t, cycle, 0, 5, band=0.1)
    assert r.oscillating and r.settling_s is None and r.verdict() == "oscillates"
    still = 5 + rng.normal(0, 0.05, len(t))  # sensor noise of half the band: settled, not oscillating
    still[:50] = np.linspace(0, 5, 50)
    r = analyse(t, still, 0, 5, band=0.1, smooth=10)
    assert not r.oscillating
    creep = 5 - 0.5 * np.exp(-t / 5)  # a slow creep: not settled, not oscillating
    r = analyse(t, creep, 0, 5, band=0.1)
    assert not r.oscillating and r.settling_s is None and r.verdict() == "does not settle"


def test_best_prefers_settled_then_fast_and_refuses_big_overshoot():
    t = np.arange(0, 3.0, 0.001)
    slow = analyse(t, second_order(0.9, 8, t), 0, 1, 0.02)
    fast = analyse(t, second_order(0.7, 20, t), 0, 1, 0.02)
    wild = analyse(t, second_order(0.2, 30, t), 0, 1, 0.02)  # 53 % overshoot
    assert best([("slow", slow), ("fast", fast), ("wild", wild)]) == 1
    assert best([("wild", wild)]) is None


def test_tune_position_on_the_virtual_board(model_calibration, tmp_path, capsys):
    with VirtualBoard(calibration=model_calibration) as vb:
        port = vb.path
        png = tmp_path / "tune.png"
        code = cli.main(["tune", "position", "--port", port, "--png", str(png), "--json",
                         "--kp", "768,%d" % OSCILLATING["kp_pos"], "--ki", "16,%d" % OSCILLATING["ki_pos"]])
        report = json.loads(capsys.readouterr().out)
        assert code == 0, report
        by_gains = {(tr["gains"]["kp_pos"], tr["gains"]["ki_pos"]): tr for tr in report["trials"]}
        default = by_gains[(768, 16)]
        assert default["verdict"] == "settles" and default["settling_s"] < 1.0 and abs(default["steady_error"]) < 50
        assert by_gains[(OSCILLATING["kp_pos"], OSCILLATING["ki_pos"])]["verdict"].startswith("oscillates")
        assert report["recommended"] is not None and report["recommended"] != OSCILLATING
        assert png.stat().st_size > 10000
        with BoardClient(port) as board:  # the gains in force before are back
            assert (board.call("get", "kp_pos"), board.call("get", "ki_pos")) == (768, 16)
            assert board.call("status")["mode"] == "idle"


OSCILLATING = {"kp_pos": 32767, "ki_pos": 4096}  # found on the virtual board: see the test above


def test_tune_force_against_the_gauge_on_the_virtual_board(model_calibration, tmp_path, capsys):
    """Force mode needs something to push against: the virtual rig's force gauge (--load gauge).
    The default gains settle on a 2 N step, and the figures come in N."""
    png = tmp_path / "force.png"
    code = cli.main(["tune", "force", "--port", "sim", "--calibration", model_calibration, "--load", "gauge",
                     "--png", str(png)])
    out = capsys.readouterr().out
    assert code == 0, out
    assert "force loop, step -1 -> -3 N" in out and "settles" in out and png.stat().st_size > 10000


def test_tune_force_with_nothing_to_push_against_says_so(model_calibration, tmp_path, capsys):
    """No load: force mode drives the block to a stroke end and nothing settles. The advice is
    host force's ("hook a load"), not "try smaller gains", which would send a person tuning."""
    code = cli.main(["tune", "force", "--port", "sim", "--calibration", model_calibration, "--duration", "0.5",
                     "--png", str(tmp_path / "force.png")])
    out = capsys.readouterr().out
    assert code == 1, out
    assert "nothing to push against" in out and "smaller gains" not in out, out
