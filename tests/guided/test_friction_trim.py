"""The friction trim's arithmetic (host/guided/friction_trim.py): which holds load, which unload,
what a too-large or too-small h and an F0 error leave in estimate - gauge, and when h is kept."""

import math

from host.guided.friction_trim import trim_magnitudes, trimmed_friction


def holds(magnitudes, f0_error_n, h_error_n, gauges=None):
    """Rows as the holds give them when the estimate's F0 is off by f0_error_n and its h by
    h_error_n (h too large: the estimate reads low while loading, high while unloading)."""
    rows, previous = [], 0.5
    for i, m in enumerate(magnitudes):
        loading = m > previous
        est = m + f0_error_n + (-h_error_n if loading else h_error_n)
        rows.append((m, est, m if gauges is None else gauges[i]))
        previous = m
    return rows


def test_an_h_too_large_is_trimmed_down_and_an_f0_error_does_not_move_it():
    m = trim_magnitudes(16.0)
    assert m == [4.8, 9.6, 14.4, 9.6, 4.8]
    trim = trimmed_friction(0.60, {1: holds(m, 0.03, 0.07), -1: holds(m, -0.02, 0.07)})
    assert math.isclose(trim.friction_n, 0.53, abs_tol=1e-9) and trim.holds == 10 and not trim.why, trim
    assert math.isclose(trim.loading_mn, 5 - 70, abs_tol=1e-6) and math.isclose(trim.unloading_mn, 5 + 70, abs_tol=1e-6)
    # what is left once h is trimmed is F0's error, the same at every force of a side
    assert not trim.f0.why, trim.f0
    for sign, f0_error in ((1, 0.03), (-1, -0.02)):
        assert [m for m, _ in trim.f0.errors[sign]] == [4.8, 9.6, 14.4]
        assert all(math.isclose(c, f0_error, abs_tol=1e-9) for _, c in trim.f0.errors[sign]), trim.f0


def test_an_h_too_small_is_trimmed_up():
    trim = trimmed_friction(0.25, {1: holds(trim_magnitudes(10.0), 0.0, -0.05)})
    assert math.isclose(trim.friction_n, 0.30, abs_tol=1e-9), trim


def test_slack_holds_are_left_out_and_one_direction_alone_keeps_h():
    m = trim_magnitudes(16.0)
    slack_unloading = holds(m, 0.0, 0.1, gauges=[4.8, 9.6, 14.4, 0.1, 0.2])
    trim = trimmed_friction(0.5, {1: slack_unloading})
    assert trim.friction_n == 0.5 and trim.holds == 3 and "no target held both loading and unloading" in trim.why, trim
    assert trim.f0.why, trim.f0  # and F0 is not corrected from holds that could not tell friction from F0


def test_a_trim_beyond_half_of_h_and_200_mN_is_not_trusted():
    trim = trimmed_friction(0.6, {1: holds(trim_magnitudes(16.0), 0.0, 0.35)})
    assert trim.friction_n == 0.6 and "more than 50 %" in trim.why and trim.f0.why, trim
    small = trimmed_friction(0.18, {1: holds(trim_magnitudes(16.0), 0.0, -0.12)})  # 67 % of a small h, but 120 mN
    assert math.isclose(small.friction_n, 0.30, abs_tol=1e-9) and not small.why, small
