"""The calibration and the experiments follow the actuator's stroke (host/guided/stroke.py), and the
firmware's soft limits start from the board file's (firmware/board_config.py, app.py)."""

import json

import pytest

from host.guided import stroke
from host.guided.flow import Options, follow_the_actuator
from testkit.actuators import frame_low, with_stroke
from testkit.interpreters import REPO


def test_the_papers_stroke_gives_the_papers_numbers():
    s = stroke.nominal({}, None)
    assert s == (0.0, 60.0)
    assert stroke.position_targets(s) == (1, 5, 10, 15, 20, 25, 30, 35, 40, 45, 50, 55, 59)
    assert stroke.middle(s) == 30.0 and stroke.min_sweep_mm(s) == 54.0 and stroke.gauge_anchor_mm(s) == 45.0


@pytest.mark.parametrize("length", [45.0, 52.5, 58.0, 65.0, 80.0])
def test_another_stroke_scales_every_number(length):
    low = frame_low(length)  # 0, or below 0 for a stroke longer than 58 mm (80 mm: -22..58)
    board = with_stroke(json.loads((REPO / "boards" / "sim.json").read_text()), length, low)
    s = stroke.nominal(board, board["actuator"])
    assert s == (low, low + length) and s[1] <= 58.0
    targets = stroke.position_targets(s)
    assert targets[0] == low + 1.0 and targets[-1] == low + length - 1.0 and all(b > a for a, b in zip(targets, targets[1:]))
    assert all(abs(t - 5 * round(t / 5)) < 1e-9 for t in targets[1:-1])  # the 5 mm grid between the ends
    assert stroke.middle(s) == low + length / 2 and stroke.min_sweep_mm(s) == pytest.approx(0.9 * length)


def test_the_end_targets_stay_inside_the_soft_limits_in_force():
    """Measured end stops -0.72 and 59.15 mm, soft limits 0.5 and 58.2 mm (an eval actuator whose
    end targets landed on the limits and never settled): the ends move 0.5 mm inside the limits;
    limits wider than the stroke change nothing."""
    targets = stroke.position_targets((-0.722, 59.148), (0.5, 58.2))
    assert targets[0] == 1.0 and targets[-1] == 57.7 and 55.0 in targets
    assert stroke.position_targets((0.0, 60.0), (0.5, 59.5)) == stroke.position_targets((0.0, 60.0))


def test_the_board_file_stroke_comes_before_the_simulated_actuators_and_bad_ones_are_refused():
    assert stroke.nominal({"stroke_mm": [2, 47]}, {"block": {"stroke_mm": [0, 60]}}) == (2.0, 47.0)
    assert stroke.nominal({}, {"block": {"stroke_mm": [0, 45]}}) == (0.0, 45.0)
    for bad in ([0, 80], [10, 5], [-70, 0]):
        with pytest.raises(ValueError):
            stroke.nominal({"stroke_mm": bad})


def test_the_guided_options_follow_the_session_unless_given():
    class Session:
        board = {"name": "sim", "stroke_mm": [0.0, 45.0]}
        actuator = None

    opts = follow_the_actuator(Options(), Session())
    assert opts.stroke == (0.0, 45.0) and opts.limits.min_range_mm == pytest.approx(40.5) and opts.anchor_mm == 33.8
    assert opts.limits.min_stops_mm == pytest.approx(36.0)  # 80 % of 45 mm, not the 0-60 mm default's 48
    given = follow_the_actuator(Options(anchor_mm=30.0), Session())
    assert given.anchor_mm == 30.0


def test_the_firmware_starts_its_soft_limits_inside_the_board_files_stroke(tmp_path):
    from firmware.board_config import BoardError, check_board
    from testkit import model
    from testkit.replay import load, replay_app

    data = model.write_replay_data(tmp_path, steps=20)
    board = json.loads((REPO / "boards" / "sim.json").read_text())
    path = tmp_path / "b45.json"
    path.write_text(json.dumps(dict(board, stroke_mm=[0, 45])))
    app, _ = replay_app(load(data), calibration=None, board_path=str(path))
    table = {row[0]: row for row in app.params()}
    assert table["stroke_min_um"][1:3] == [500, 500] and table["stroke_max_um"][1:3] == [44500, 44500]
    plain, _ = replay_app(load(data), calibration=None)  # no stroke_mm: the table's 0-60 mm defaults
    assert {row[0]: row[1] for row in plain.params()}["stroke_max_um"] == 59500
    for bad in ([0, 80], [5, 5], "0-45", [0]):
        with pytest.raises(BoardError, match="stroke_mm"):
            check_board(dict(board, stroke_mm=bad))


@pytest.mark.parametrize("length,low", [(45.0, 0.0), (80.0, -22.0)])
def test_the_model_calibration_spans_the_boards_own_stroke(length, low):
    """testkit.model's exact pot tables (the offline benches' --exact, the firmware tests) follow
    the block over the board's stroke: at each end the table gives where the wiper is (until stop
    41 they spanned 0-60 mm, and a drawn 43 mm actuator read 2-7 % force errors that were the
    tables', not the loop's)."""
    from boards.sim.actuator import Actuator
    from firmware.pwl_fixed import pwl
    from testkit import model

    board = with_stroke(model.sim_board(), length, low)
    sections = model.model_sections(board)
    world = Actuator(dict(board["actuator"], adc_bits=board["adc_bits"]), 1)
    for x in (low + 0.5, low + length / 2.0, low + length - 0.5):
        world.place(x)
        for i, name in enumerate(("pot1", "pot2")):
            travel_um = 1000.0 * (x + world.pots[i].mount_error_mm(x))
            assert abs(pwl(world.true_code(name), sections[name]["fixed"]) - travel_um) < 40.0, (name, x)
