"""Bench commands on the virtual board with a load on the block (`--load`): `host force` settles
against the simulated force gauge and says in one line when it cannot (no load: Fig. 8's run to
a stroke end). The real unix port, firmware, pty and pyserial, through the host CLI."""

import json
import re

import pytest

from boards.sim import bench_rig, machine
from host import cli
from host.link.telemetry_log import load
from host.link.bench_load import parse_load
from testkit.interpreters import REPO


BOARD = json.loads((REPO / "boards" / "sim.json").read_text())


def test_parse_load_takes_the_documented_forms_and_refuses_the_rest():
    assert parse_load("none") == {"kind": "none"}
    assert parse_load("gauge") == {"kind": "gauge", "side": "high"}  # anchored where the board file says
    assert parse_load("gauge@40.5") == {"kind": "gauge", "side": "high", "anchor_mm": 40.5}
    assert parse_load("gauge-low@20") == {"kind": "gauge", "side": "low", "anchor_mm": 20.0}
    assert parse_load("constant:-2.5") == {"kind": "constant", "force_n": -2.5}
    assert parse_load("gauge@0") == {"kind": "gauge", "side": "high", "anchor_mm": 0.0}
    assert parse_load("constant:100") == {"kind": "constant", "force_n": 100.0}
    for bad in ("", "gauge@", "gauge@x", "gauge:40", "constant", "constant:", "constant:nan", "none:1", "spring", "gaugex", "gauge-high",
                "gauge@-1e308", "gauge-low@66", "gauge@inf", "constant:1e308", "constant:-101", "constant:-inf"):
        with pytest.raises(ValueError, match=re.escape("load must be none, gauge[@MM], gauge-low[@MM] or constant:N")):
            parse_load(bad)


def test_rig_file_constant_load_pushes_the_block(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    world = machine.configure(BOARD, seed=3)
    (tmp_path / "rig.json").write_text(json.dumps({"load": parse_load("constant:-2.5")}))
    bench_rig.poll(world)
    assert world.load_kind == "constant" and world.external_force_n == -2.5
    start = world.block_mm
    world.advance(0.2)
    assert world.block_mm < start - 1.0  # 2.5 N toward 0 mm beats 0.3 N of friction


def test_load_on_a_real_port_is_a_one_line_error(capsys):
    assert cli.main(["status", "--port", "/dev/ttyACM9", "--load", "gauge"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("error: a load can be hooked only on a virtual board (port sim)")


def test_bad_load_is_refused_by_the_parser(capsys):
    assert cli.main(["force", "--port", "sim", "--load", "spring", "--target", "-5"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "load must be none, gauge[@MM], gauge-low[@MM] or constant:N" in err


def test_help_of_sim_and_force_tells_how_to_hook_a_load(capsys):
    for command in ("sim", "force"):
        assert cli.main([command, "--help"]) == 0
        text = " ".join(capsys.readouterr().out.split())
        assert "--load none|gauge[@MM]|gauge-low[@MM]|constant:N" in text and "force gauge" in text


def test_force_on_port_sim_with_the_gauge_settles_on_the_target(model_calibration, capsys):
    code = cli.main(["force", "--port", "sim", "--load", "gauge@40", "--calibration", model_calibration, "--target", "-5"])
    out = capsys.readouterr().out
    assert code == 0, out
    assert out.startswith("reached at ")
    assert abs(float(out.split()[2]) + 5.0) <= 0.1  # the firmware's F0(d), mean of the last 0.1 s


def test_positive_force_on_port_sim_settles_against_a_gauge_on_the_low_side(model_calibration, capsys):
    code = cli.main(["force", "--port", "sim", "--load", "gauge-low@20", "--calibration", model_calibration, "--target", "5"])
    out = capsys.readouterr().out
    assert code == 0, out
    assert abs(float(out.split()[2]) - 5.0) <= 0.1


def test_a_force_beyond_what_the_calibration_held_is_refused_in_one_line(capsys):
    """The ready calibration's force step held about 17.9 N a side: -150 N (which the protocol's
    +-200 N allows) is refused by the board with the range, not run to the end of F0's table."""
    code = cli.main(["force", "--port", "sim", "--load", "gauge", "--target", "-150"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1, err
    assert "force target -150000 mN is beyond what the force calibration held (-1" in err, err


def test_force_at_no_load_says_in_one_line_that_it_did_not_settle(model_calibration, capsys):
    # Nothing to push against: the block runs toward 0 mm until the soft stroke limit holds it
    # (Fig. 8 of the paper), and the force never builds up. Measured and missed: status 1, as host move.
    code = cli.main(["force", "--port", "sim", "--calibration", model_calibration, "--target", "-5", "--timeout", "10"])
    captured = capsys.readouterr()
    assert code == 1
    lines = [line for line in captured.out.split("\n") if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("NOT settled at ") and "(target -5.000 N)" in lines[0]
    # the limit it stopped at is the one in force (0.5 mm inside boards/sim.json's 0-60 mm), not a made-up end
    assert "at the soft stroke limit (0.5 mm): nothing to push against? hook a load (--port sim: --load gauge)" in lines[0]


def test_a_move_held_back_by_a_load_says_the_motor_is_at_its_duty_limit(model_calibration, capsys):
    """The gauge (on the 0 mm side) goes taut once the block passes 40 mm, and it is far stiffer than the motor is strong
    beyond it: the move toward 50 mm stops short with the duty at out_limit, and says so (it used
    to say only "NOT settled")."""
    code = cli.main(["move", "--port", "sim", "--load", "gauge-low@40", "--calibration", model_calibration, "--to", "50",
                     "--timeout", "3", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == 1 and not out["reached"] and out["value"] < 45, out
    assert "duty limit" in out["cause"] and "against" in out["cause"], out["cause"]


def test_log_and_plot_from_a_calibrated_board_warn_of_nothing(model_calibration, tmp_path, capsys):
    out = tmp_path / "run.csv"
    assert cli.main(["log", "--port", "sim", "--calibration", model_calibration, "--out", str(out), "--seconds", "0.5", "--rate", "100"]) == 0
    assert "warning" not in capsys.readouterr().err
    data = load(out)
    assert len(data["t_us"]) > 20 and abs(data["d2_um"].mean() - 30000) < 1000  # the block boots at 30 mm
    assert cli.main(["plot", str(out)]) == 0
    assert capsys.readouterr().err == "" and out.with_suffix(".png").stat().st_size > 10000


def test_stop_and_reset_leave_the_board_ready_to_move_again(model_calibration, capsys):
    """The reported sequence on one virtual board: move --hold, the host goes quiet and the
    watchdog latches host_timeout, then `host stop` clears it (named), and the next move runs;
    `host reset` names and clears any latched fault; `host status` shows every field (timing,
    stroke limits) and --json gives the firmware's object."""
    import time

    from host.link.virtual_board import VirtualBoard

    with VirtualBoard(calibration=model_calibration) as vb:
        port = vb.path
        assert cli.main(["move", "--port", port, "--to", "25", "--hold"]) == 0
        time.sleep(1.5)
        capsys.readouterr()
        assert cli.main(["status", "--port", port, "--json"]) == 0
        st = json.loads(capsys.readouterr().out)
        assert st["faults"] == ["host_timeout"], st
        for key in ("step_us_max", "overruns", "period_us", "stroke_um", "steps", "duty", "timer", "last_exit"):
            assert key in st, key
        assert cli.main(["stop", "--port", port]) == 0
        out = capsys.readouterr().out
        assert "cleared host_timeout" in out and out.rstrip().endswith("stopped"), out
        assert cli.main(["move", "--port", port, "--to", "30"]) == 0, capsys.readouterr()
        capsys.readouterr()
        assert cli.main(["reset", "--port", port]) == 0
        assert capsys.readouterr().out.strip() == "no latched faults"
        assert cli.main(["status", "--port", port]) == 0
        text = capsys.readouterr().out
        assert "longest step (us)" in text and "overruns" in text and "soft stroke limits on D2 (um)" in text
        assert "latched faults                 none" in text, text
