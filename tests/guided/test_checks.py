"""The pot sweep checks accept a good sweep and reject each kind of bad one (synthetic arrays)."""

import numpy as np
import pytest

from host.guided.checks import Limits, check_sweep

BITS = 12


def knee_sweep(lo_mm=0.0, hi_mm=60.0, n=1500, noise_mm=0.01, hyst_mm=0.0, seed=1):
    """Forward and backward runs of a knee-shaped pot (codes) against a reference (mm)."""
    rng = np.random.default_rng(seed)
    pos = np.linspace(lo_mm, hi_mm, n)
    u = (pos + 5) / 70
    frac = 0.03 + 0.94 * (u + 0.08 * np.sin(np.pi * u) ** 3)  # increasing, knees near the ends
    raw = np.round(frac / frac.max() * 3900 + rng.normal(0, 1.0, n))
    raw2 = raw[::-1]
    ref_f = pos + rng.normal(0, noise_mm, n) + hyst_mm
    ref_b = pos[::-1] + rng.normal(0, noise_mm, n) - hyst_mm
    return np.concatenate([raw, raw2]), np.concatenate([ref_f, ref_b]), np.concatenate([np.ones(n), -np.ones(n)])


def failed(checks):
    return {c.name for c in checks if not c.ok}


def test_good_sweep_passes_every_check():
    raw, ref, d = knee_sweep()
    checks, noise, hyst = check_sweep(raw, ref, d, BITS)
    assert failed(checks) == set()
    assert 0.003 < noise < 0.05
    assert abs(hyst) < 0.01


def test_too_little_range_is_refused_with_advice():
    raw, ref, d = knee_sweep(20.0, 45.0)
    checks, _, _ = check_sweep(raw, ref, d, BITS)
    assert failed(checks) == {"range"}
    assert "end to end" in [c for c in checks if c.name == "range"][0].advice


def test_noisy_sweep_is_refused():
    raw, ref, d = knee_sweep(noise_mm=0.2)
    checks, noise, _ = check_sweep(raw, ref, d, BITS)
    assert "noise" in failed(checks)
    assert noise > 0.1


def test_rail_clipped_samples_are_refused():
    raw, ref, d = knee_sweep()
    raw[100:140] = (1 << BITS) - 1  # a wiper lifting off mid-sweep reads full scale
    checks, _, _ = check_sweep(raw, ref, d, BITS)
    assert "rails" in failed(checks)


def test_backlash_between_directions_is_refused():
    raw, ref, d = knee_sweep(hyst_mm=0.2)
    checks, _, hyst = check_sweep(raw, ref, d, BITS)
    assert failed(checks) == {"hysteresis"}
    assert hyst == pytest.approx(0.2, abs=0.02)


def test_reference_mounted_the_other_way_round_is_not_monotone():
    raw, ref, d = knee_sweep()
    checks, _, _ = check_sweep(raw, 60.0 - ref, d, BITS)
    assert failed(checks) == {"monotone"}
    assert "mounted on THIS pot" in [c for c in checks if c.name == "monotone"][0].advice


def test_a_slipping_coupling_is_not_monotone():
    raw, ref, d = knee_sweep()
    slip = ref.copy()
    fwd = np.flatnonzero(d == 1)
    slip[fwd[600:]] -= 3.0  # the reference jumped back 3 mm half-way through the forward run
    slip[np.flatnonzero(d == -1)[:900]] -= 3.0
    checks, _, _ = check_sweep(raw, slip, d, BITS)
    assert "monotone" in failed(checks)


def test_almost_no_data_is_one_clear_failure():
    checks, _, _ = check_sweep(np.arange(5.0), np.arange(5.0), None, BITS)
    assert [c.name for c in checks] == ["samples"] and not checks[0].ok


def test_limits_are_adjustable():
    raw, ref, d = knee_sweep(10.0, 50.0)
    assert "range" in failed(check_sweep(raw, ref, d, BITS)[0])
    assert "range" not in failed(check_sweep(raw, ref, d, BITS, Limits(min_range_mm=35.0))[0])


def test_a_pot_whose_mount_shrinks_its_scale_is_checked_against_its_own_end_stops():
    # One drawn actuator (seed 202611271902): a 40.5 mm stroke read 36.0 mm between the block's
    # end stops with the reference on pot 2 (its mount error shrinks the scale), 43.2 on pot 1.
    from host.guided.pot_calibration import sweep_limits

    nominal = Limits(min_range_mm=0.9 * 40.5, min_stops_mm=0.8 * 40.5)
    raw, ref, d = knee_sweep(0.0, 36.0)
    assert "range" in failed(check_sweep(raw, ref, d, BITS, nominal)[0])
    shrunk, stops = sweep_limits(nominal, {"low": (1.6, 1700), "high": (37.6, 3900)})
    assert shrunk.min_range_mm == pytest.approx(0.9 * 36.0)
    assert failed(check_sweep(raw, ref, d, BITS, shrunk)[0] + stops) == set()
    stretched, stops = sweep_limits(nominal, {"low": (-1.0, 1700), "high": (42.2, 3900)})
    assert stretched.min_range_mm == nominal.min_range_mm and failed(stops) == set()  # never looser than nominal there
    jammed, stops = sweep_limits(nominal, {"low": (1.6, 1700), "high": (21.6, 2600)})
    assert failed(stops) == {"stops"} and "jams" in stops[0].advice
    assert sweep_limits(nominal, None) == (nominal, [])  # stops not measured (a manual reference): the nominal range


def test_the_df_sweep_is_checked_against_the_end_stops_the_pots_step_measured():
    # One drawn actuator (seed 202611272311): a 43.8 mm stroke, its end stops 38.7 mm apart in D2;
    # the Df sweep covered 37.9 mm and failed the nominal 0.9 x 43.8 = 39.4 mm.
    from host.guided.assembly_calibration import min_sweep_mm

    nominal = Limits(min_range_mm=0.9 * 43.8, min_stops_mm=0.8 * 43.8)
    assert min_sweep_mm(nominal, [1100, 39800]) == pytest.approx(0.9 * 38.7)
    assert 37.9 >= min_sweep_mm(nominal, [1100, 39800])
    assert min_sweep_mm(nominal, [-1500, 45000]) == nominal.min_range_mm  # never looser than nominal there
    assert min_sweep_mm(nominal, None) == nominal.min_range_mm  # no stops measured (a manual reference)
