"""Positions measured from the block's end stops, whatever part of the assembly error pot 2 carries.

The reference sensor rides on pot 2's wiper, so pot 2's own mounting error moves and stretches
the frame it calibrates D2 in: with 40 % of sim.json's assembly error on pot 2 (the rest on
pot 1, Df unchanged) the block's end stops sit at -1.84 and 58.52 mm of the reference, and a
calibration in the reference's own frame could never reach the 1 mm target (nor keep its soft
limit off the 60 mm stop). The pots step measures the stops and centres the frame on them; the
firmware keeps its soft limits a margin inside them; the experiment zeroes its reference on the
same stops. The real firmware on the virtual board, through the guided pots step.
"""

import json

import numpy as np
import pytest

from host.calibration.file import read_calibration
from host.cli import build_parser
from host.commands.calibrate import calibrate


@pytest.fixture(scope="module")
def split_board(tmp_path_factory):
    board = json.loads(open("boards/sim.json").read())
    pots = board["actuator"]["pots"]
    shape = pots["pot1"]["mount_error"]["coeffs_mm"]
    pots["pot1"]["mount_error"]["coeffs_mm"] = [0.6 * c for c in shape]
    pots["pot2"]["mount_error"]["coeffs_mm"] = [-0.4 * c for c in shape]  # Df = e1 - e2 as before
    board.pop("sources", None)
    path = tmp_path_factory.mktemp("split") / "split.json"
    path.write_text(json.dumps(board))
    e2 = [float(np.polyval([-0.4 * c for c in shape][::-1], v)) for v in (-1.0, 1.0)]
    return path, e2


def test_the_end_stops_frame_the_stroke_and_both_ends_are_reached(split_board, tmp_path):
    from host.experiments import displacement
    from host.guided.prompts import Prompter
    from host.guided.rig import Rig, reference_scale
    from host.guided.session import Session

    board_path, (e2_low, e2_high) = split_board
    out = tmp_path / "calibration.json"
    args = build_parser().parse_args(["calibrate", "pots", "--port", "sim", "--board", str(board_path), "--out", str(out),
                                      "--yes", "--duty", "3000"])
    said = []
    calibrate(args, say=said.append)
    lo, hi = read_calibration(out)["stroke"]["end_stops_mm"]
    length = 60.0 + e2_high - e2_low  # the stroke as pot 2's wiper (and the reference) sees it
    assert e2_low < -1.5  # the reference's own frame would put the low stop 1.8 mm below zero
    assert abs((lo + hi) / 2 - 30.0) < 0.1 and abs((hi - lo) - length) < 0.15, (lo, hi, length)
    prompter = Prompter(yes=True, out=lambda s: None)
    with Session("sim", str(board_path), out, say=lambda s: None) as session:
        status = session.client.call("status")
        assert status["end_stops_um"] == [round(lo * 1000), round(hi * 1000)]
        # the soft limits: the parameters (0.5, 59.5 mm), but never within stop_margin_um of a stop
        assert status["stroke_um"] == [max(500, round(lo * 1000) + 300), min(59500, round(hi * 1000) - 300)]
        scale = reference_scale(session.actuator)
        rig = Rig(prompter, session.virtual)
        zero = displacement.zero_at_stops(session, rig, scale)
        rows = displacement.run_targets(session, rig, scale, zero, targets=(1, 30, 59))
    assert all(r["settled"] for r in rows), rows
    assert displacement.max_error(rows) <= 0.1, rows


@pytest.mark.parametrize("length, low", [(45.0, 0.0), (80.0, -22.0)])
def test_another_stroke_calibrates_in_its_own_frame_and_reaches_both_ends(tmp_path, length, low):
    """Actuators with a 45 mm and an 80 mm stroke (testkit.actuators.with_stroke; the 80 mm one
    on -22..58 mm, testkit.actuators.frame_low, as the board's positions end at 65.5 mm): the pot
    check asks for 90 % of the stroke, not of 60 mm; the frame's middle is the stroke's; the
    firmware's soft limits start from the board file's stroke; the targets 1 mm inside each end
    are reached."""
    from host.experiments import displacement
    from host.guided import stroke
    from host.guided.prompts import Prompter
    from host.guided.rig import Rig, reference_scale
    from host.guided.session import Session
    from testkit.actuators import with_stroke

    board = with_stroke(json.loads(open("boards/sim.json").read()), length, low)
    board.pop("sources", None)
    board_path = tmp_path / "board.json"
    board_path.write_text(json.dumps(board))
    out = tmp_path / "calibration.json"
    args = build_parser().parse_args(["calibrate", "pots", "--port", "sim", "--board", str(board_path), "--out", str(out),
                                      "--yes", "--duty", "3000"])
    said = []
    calibrate(args, say=said.append)
    assert any("check ok   range" in line and "(limit %g)" % (0.9 * length) in line for line in said), said
    middle, high = low + length / 2, low + length
    lo, hi = read_calibration(out)["stroke"]["end_stops_mm"]
    assert abs((lo + hi) / 2 - middle) < 0.1 and abs((hi - lo) - length) < 0.15, (lo, hi)
    with Session("sim", str(board_path), out, say=lambda s: None) as session:
        status = session.client.call("status")
        assert status["stroke_um"] == [max(round(low * 1000) + 500, round(lo * 1000) + 300),
                                       min(round(high * 1000) - 500, round(hi * 1000) - 300)]
        s = stroke.nominal(session.board, session.actuator)
        rig = Rig(Prompter(yes=True, out=lambda s: None), session.virtual)
        scale = reference_scale(session.actuator)
        zero = displacement.zero_at_stops(session, rig, scale, middle_mm=stroke.middle(s))
        rows = displacement.run_targets(session, rig, scale, zero, targets=(low + 1.0, middle, high - 1.0))
    assert all(r["settled"] for r in rows), rows
    assert displacement.max_error(rows) <= 0.1, rows
