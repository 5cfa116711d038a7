"""The firmware's safety rules (tests/firmware/safety_cases.py), each run under CPython and
MicroPython: a wiper lift, host silence in every motion mode, an exception in the step and
KeyboardInterrupt in run() each leave the bridge off; stop() turns it off at once, and
board_main.run turns it off whatever escapes the App; every command counts as hearing the
host."""

import pytest

from tests.firmware.on_both import runner

CASES = "tests.firmware.safety_cases"
both = runner(CASES)


@pytest.mark.parametrize("pot", ["pot1", "pot2"])
def test_wiper_lift_stops_motor_within_one_period(data_path, pot):
    here, there = both("case_rail_fault(PATH, %r)" % pot, data_path)
    assert here == there


def test_host_silence_stops_motor(data_path):
    here, there = both("case_host_timeout(PATH)", data_path)
    assert "50 ms" in here["fault"] and here == there


def test_exception_in_step_leaves_pwm_zero(data_path):
    here, there = both("case_step_exception(PATH)", data_path)
    assert "OSError" in here["fault"] and "OSError" in there["fault"]


def test_stop_turns_the_bridge_off_at_once(data_path):
    """App.stop (what the `stop` command and every exit call) leaves both PWM outputs at 0 before
    the next control step, not only the duty the next step would write."""
    here, there = both("case_stop_turns_the_bridge_off(PATH)", data_path)
    assert here == there and here["running"] > 0


def test_board_main_stops_the_motor_whatever_escapes_the_app(data_path):
    """board_main.run's last line of defence: an App.run that ends by an exception with the bridge
    still driven (its own shutdown failed or was bypassed) leaves it off once run returns."""
    here, there = both("case_board_main_stops_what_run_left_running(PATH)", data_path)
    assert here == there and here["during"] > 0 and here["after"] == [0, 0]


def test_keyboard_interrupt_in_run_leaves_pwm_zero(data_path):
    here, there = both("case_keyboard_interrupt(PATH)", data_path)
    assert here["duty_seen"] > 0 and here == there


def test_watchdog_stops_every_motion_mode(data_path):
    here, there = both("case_watchdog_in_every_motion_mode(PATH)", data_path)
    assert here == there


def test_every_command_counts_as_hearing_the_host(data_path):
    here, there = both("case_commands_count_as_hearing_the_host(PATH)", data_path)
    assert here == there
