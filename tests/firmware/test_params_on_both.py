"""The App's parameters and targets (tests/firmware/param_cases.py), each case run under CPython
and MicroPython: targets and parameters out of range refused, the boot values back after a
silent host's motion, temporary values back after host_timeout_ms of silence, soft limits that
must leave a stroke (set by the host or saved in the params file)."""

from testkit import interpreters
from tests.firmware.on_both import runner

CASES = "tests.firmware.param_cases"
both = runner(CASES)


def test_targets_and_parameters_out_of_range_are_refused(data_path):
    here, there = both("case_range_checks(PATH)", data_path)
    assert here == there


def test_a_silent_host_gets_the_boot_parameters_back(data_path):
    here, there = both("case_host_silence_restores_params(PATH)", data_path)
    assert here == there and here["restored_at"] == 50


def test_temporary_parameters_come_back_when_the_host_goes_silent(data_path):
    here, there = both("case_temporary_params_come_back_when_the_host_goes_silent(PATH)", data_path)
    assert here == there


def test_stroke_limits_must_leave_a_stroke(data_path, tmp_path):
    """Inverted soft limits (each within its range) were accepted by `set` and from params.txt, and
    every later move was then refused; a random params.txt was refused with a blank reason."""
    junk = tmp_path / "junk.txt"
    junk.write_bytes(bytes(range(128, 256)) * 8)
    call = "case_stroke_limits_must_leave_a_stroke(PATH, %r, %r)"
    here = interpreters.on_cpython(CASES, call.replace("PATH", repr(data_path)) % (str(tmp_path / "a.txt"), str(junk)))
    there = interpreters.on_micropython(CASES, call.replace("PATH", repr(data_path)) % (str(tmp_path / "b.txt"), str(junk)))
    for out in (here, there):
        assert out["refused"] == 4 and "would leave no stroke" in out["first"], out
        assert "stroke_min_um 40000 not below stroke_max_um 30000" in out["file_error"], out
        assert out["stroke"] == [500, 59500], out
        assert out["junk_error"].split("unusable:")[1].strip(), out
