"""The loop timer per board file and why run() ended (tests/firmware/loop_cases.py), on CPython
and the real MicroPython."""

import pytest

from testkit import model
from testkit.interpreters import on_cpython, on_micropython, same

CASES = "tests.firmware.loop_cases"


@pytest.fixture(scope="module")
def data_path(tmp_path_factory):
    return model.write_replay_data(tmp_path_factory.mktemp("loop"), steps=300, duty=3000)


def both(call):
    return same(CASES, call)


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


@pytest.mark.parametrize(
    "how,raised,faults",
    [
        ("ctrl_c", "KeyboardInterrupt", ["interrupted"]),
        ("soft_reset", "SystemExit", ["soft_reset"]),  # machine.soft_reset() on MicroPython
        ("exception", "OSError", ["run_exception"]),
        ("quit", None, []),
    ],
)
def test_run_records_why_it_ended_and_the_next_boot_reads_it(data_path, tmp_path, how, raised, faults):
    call = "case_exit_cause(%r, %%r, %r)" % (data_path, how)
    here = on_cpython(CASES, call % str(tmp_path / "here.txt"))
    there = on_micropython(CASES, call % str(tmp_path / "there.txt"))
    assert here == there
    assert here["raised"] == raised and here["faults"] == faults
    assert here["exit"] == (faults[0] if faults else "returned")
    texts = [(tmp_path / name).read_text() for name in ("here.txt", "there.txt")]
    if how == "exception":  # repr(OSError(5)) is "OSError(5)" on CPython, "OSError(5,)" on MicroPython
        texts = [t.replace("(5,)", "(5)") for t in texts]
    assert texts[0] == texts[1]


def test_an_exit_that_never_reached_finally_is_reported_as_such(data_path, tmp_path):
    call = "case_exit_unrecorded(%r, %%r)" % data_path
    here = on_cpython(CASES, call % str(tmp_path / "here.txt"))
    there = on_micropython(CASES, call % str(tmp_path / "there.txt"))
    assert here == there and "power loss" in here["marker"]
