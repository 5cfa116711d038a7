"""The loop timer per board file (tests/firmware_loop_cases.py), on CPython and the real MicroPython."""

import json

import pytest

import firmware_loop_cases
from micropython_runner import REPO, run_micropython


def on_micropython(call):
    proc = run_micropython(
        "import json, firmware_loop_cases\nprint(json.dumps(firmware_loop_cases.%s))\n" % call,
        extra_paths=[REPO / "tests"],
    )
    return json.loads(proc.stdout.strip().splitlines()[-1])


def both(call):
    here = eval("firmware_loop_cases." + call)
    there = on_micropython(call)
    assert here == there
    return here


PERIODIC = [["callback", "step"], ["freq", 1000], ["mode", 1]]


@pytest.mark.parametrize(
    "board,calls,kind",
    [
        # rp2: the virtual timer with hard=True (a hard IRQ from MicroPython 1.26 on)
        ("pico", [["machine.Timer", -1], ["init", [["callback", "step"], ["freq", 1000], ["hard", True], ["mode", 1]]]], "hard"),
        # esp32: hardware timer 0, no hard= (the port has no hard timer callbacks)
        ("esp32_devkitc", [["machine.Timer", 0], ["init", PERIODIC]], "soft"),
        # stm32: pyb.Timer 4 with freq and callback in the constructor (hard IRQ)
        ("pyboard", [["pyb.Timer", 4, [["callback", "step"], ["freq", 1000]]]], "hard"),
        ("sim", [["machine.Timer", -1], ["init", PERIODIC]], "soft"),
    ],
)
def test_each_board_file_starts_its_loop_on_the_right_timer(board, calls, kind):
    out = both("case_loop_timer(%r)" % board)
    assert out["calls"] == calls
    assert out["timer"] == out["promised"] == kind


@pytest.mark.parametrize("refusal", ["TypeError", "ValueError"])
def test_a_port_that_refuses_hard_runs_soft_and_says_so(refusal):
    """rp2 before 1.26 has no hard= (TypeError); esp32 refuses hard=True (ValueError): the loop
    still starts, on the same timer without hard=, and status() reports soft, not hard."""
    out = both("case_loop_timer('pico', %r)" % refusal)
    hard = [["callback", "step"], ["freq", 1000], ["hard", True], ["mode", 1]]
    assert out["calls"] == [["machine.Timer", -1], ["init", hard], ["init", PERIODIC]]
    assert out["promised"] == "hard" and out["timer"] == "soft"


def test_loop_hz_must_fit_the_board_timer():
    out = both("case_loop_hz_checks()")
    assert out["shipped"] == [
        ["pico", "machine", 1000000],
        ["esp32_devkitc", "machine", 10000000],
        ["pyboard", "pyb", 84000000],
        ["sim", "machine", 1000000],
    ]
