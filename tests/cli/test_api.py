"""The Python API (host/api.py): the worked example of docs/python-api.md run as it stands against
the virtual board, and what a script relies on beyond it (the motor stopped on every way out,
records as an iterator, one-line errors)."""

import contextlib
import io
import re

import numpy as np
import pytest

from firmware import protocol as P
from host.api import Board
from host.errors import UserError
from testkit.interpreters import REPO

from testkit.model import write_model_calibration

DOC = REPO / "docs" / "python-api.md"


def example_code():
    blocks = re.findall(r"```python\n(.*?)```", DOC.read_text(), re.S)
    assert len(blocks) == 1, "docs/python-api.md has one worked example"
    return blocks[0]


def test_the_worked_example_runs_as_documented(tmp_path, monkeypatch):
    write_model_calibration(tmp_path / "cal.json", date="2026-03-03")
    monkeypatch.chdir(tmp_path)
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        exec(compile(example_code(), str(DOC), "exec"), {"__name__": "__example__"})
    out = printed.getvalue()
    assert re.search(r"^fit: \w+ order \d+, rms 0\.0\d+ mm", out, re.M), out
    assert "firmware" in out and "on sim, mode idle" in out
    assert re.search(r"^move: reached=True at (49|50)\.\d+ mm .* lost frames 0, board ring drops 0", out, re.M), out
    assert re.search(r"^force: reached=True at -(1\.9|2\.0|2\.1)\d* N", out, re.M), out
    assert "every 1 ms step there: True" in out
    assert (tmp_path / "api-example" / "fit.png").stat().st_size > 10000
    assert (tmp_path / "api-example" / "move.meta.json").is_file()


def test_closing_stops_the_motor_unless_told_not_to_and_an_exception_always_does(model_calibration):
    from host.link.board_client import BoardClient
    from host.link.virtual_board import VirtualBoard

    with VirtualBoard(calibration=model_calibration) as vb:
        with Board(vb.path) as board:
            board.client.call("mode", "position")
            board.client.call("target", 30000)
        with BoardClient(vb.path) as client:
            assert client.call("status")["mode"] == "idle"
        with Board(vb.path, stop_on_exit=False) as board:
            board.client.call("mode", "position")
            board.client.call("target", 30000)
        with BoardClient(vb.path) as client:
            assert client.call("status")["mode"] == "position"
        with pytest.raises(KeyError):
            with Board(vb.path, stop_on_exit=False) as board:
                raise KeyError("boom")
        with BoardClient(vb.path) as client:
            assert client.call("status")["mode"] == "idle"


def test_records_come_as_an_iterator_and_as_arrays_spanning_board_time(model_calibration):
    with Board("sim", calibration=model_calibration) as board:
        records = list(board.stream(seconds=0.2, rate=1000))
        run = board.record(0.3, rate=1000)
    assert records[0]._fields == P.FIELDS
    assert set(np.diff([r.t_us for r in records])) == {1000} and 195 <= len(records) <= 202
    assert set(run) == set(P.FIELDS) | {"t_s"}
    assert run["t_s"][0] == 0 and run["t_s"][-1] == pytest.approx(0.3, abs=0.002)
    assert set(np.diff(run["t_us"])) == {1000}


def test_a_move_on_a_board_without_calibration_is_a_one_line_error():
    with Board("sim", uncalibrated=True) as board:
        with pytest.raises(UserError, match="a move needs a calibrated board: this one has no usable calibration"):
            board.move(20)
        with pytest.raises(UserError, match=r"kp_pos=99999999 is outside the firmware's limits"):
            board.set_params(kp_pos=99999999)
        with pytest.raises(UserError, match="unknown parameter 'nope'"):
            board.set_params({"nope": 1})
