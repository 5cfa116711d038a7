"""The drive path (tests/firmware/drive_cases.py), each case run under CPython and MicroPython:
the motor's own clamp, the position loop's output clamp with the feed-forward, the slew limit,
the PI's anti-windup, both bridge wirings and the pyboard's PWM adapter."""

from testkit import model
from tests.firmware.on_both import runner

CASES = "tests.firmware.drive_cases"
both = runner(CASES)


def test_the_motor_clamps_both_directions(data_path):
    """The motor's own clamp, the last line before the bridge: +-20000 asked, +-10000 (full
    scale, 65535) written, on both interpreters (viper on MicroPython)."""
    here, there = both("case_motor_clamps(PATH)", data_path)
    assert here == there == {"duty": [10000, -10000], "u16": [65535, 65535]}


def test_the_position_loop_output_stays_within_out_limit_with_feed_forward(data_path, tmp_path):
    """Position mode with a friction feed-forward (the friction section's ff_duty) and the PI
    saturated: PI output plus the feed-forward is clamped to +-out_limit in both directions."""
    ff = tmp_path / "ff.json"
    model.write_model_calibration(ff, feed_forward=True)
    here, there = both("case_position_output_clamp(PATH, %r)" % str(ff), data_path)
    assert here == there
    assert here["ff_duty"] > 0 and here["duty"] == [here["out_limit"], -here["out_limit"]], here


def test_slew_limit(data_path):
    here, there = both("case_slew(PATH)", data_path)
    assert here == there


def test_pi_anti_windup():
    here, there = both("case_anti_windup()")
    assert here == there


def test_motor_wiring_two_drivers():
    here, there = both("case_motor_wiring()")
    assert here == there


def test_pyboard_pwm_adapter():
    here, there = both("case_pyboard_pwm_adapter()")
    assert here == there
