"""The gain step's arithmetic (host/guided/gain_sweep.py) on sweeps made from the simulated pot's
mounting-error model: a steady weight read along the stroke through a bowed pot 2 gives back the
slope it was read through, the block's friction (opposite in the two directions) cancels, and a
sweep that cannot give a gain says why."""

import numpy as np
import pytest

from boards.sim.potentiometer import Potentiometer
from host.errors import UserError
from host.guided import gain_sweep

ANCHOR_MM = 45.0


def _pot2(coeffs_mm):
    """Pot 2 of boards/sim.json with a mounting error of its own (mm, in v = (x - 30) / 30)."""
    from testkit.model import sim_board

    params = sim_board()["actuator"]["pots"]["pot2"]
    params = dict(params, mount_error=dict(params["mount_error"], coeffs_mm=list(coeffs_mm)))
    return Potentiometer(params)


def _slope(pot, x):
    return 1.0 + (pot.mount_error_mm(x + 0.01) - pot.mount_error_mm(x - 0.01)) / 0.02


def _residual(x):
    """What a Df fit leaves of the assembly error: tens of um in a few-mm pattern."""
    return 0.025 * np.sin(x / 2.3) + 0.01 * np.cos(x / 7.0)


def _sweep(pot, d_true_mm=-0.45, friction_mm=0.06, noise_mm=0.02, seed=3, residual=None):
    """Samples of a weighted sweep both ways over 2-58 mm: D2 is the wiper's travel, the
    deformation the spring's times pot 2's slope there, the block's friction adding to it one
    way and taking from it the other, with the pots' noise."""
    rng = np.random.default_rng(seed)
    x = np.concatenate([np.linspace(2, 58, 1500), np.linspace(58, 2, 1500)])
    direction = np.concatenate([np.ones(1500), -np.ones(1500)])
    d2 = np.array([v + pot.mount_error_mm(v) for v in x])
    defl = (d_true_mm + friction_mm * direction) * np.array([_slope(pot, v) for v in x])
    if residual is not None:
        defl = defl + residual(x)
    return d2, defl + rng.normal(0.0, noise_mm, len(x)), direction


@pytest.mark.parametrize("coeffs", [[0.4, 1.1, 0.9, -0.3, 0.6], [-0.2, -1.6, 0.4, 0.8, -0.5], [0.0] * 5],
                         ids=["bowed", "tilted", "true"])
def test_the_gain_is_pot_2s_slope_at_the_anchor_over_its_slope_there(coeffs):
    pot = _pot2(coeffs)
    d2, defl, direction = _sweep(pot)
    centres, means, counts = gain_sweep.direction_means(d2, defl, direction)
    knots, gains, stats = gain_sweep.fit_gain(centres, means, counts, ANCHOR_MM)
    x_true = [k - pot.mount_error_mm(k) for k in knots]  # the block's place at each knot (near enough)
    expected = np.array([_slope(pot, ANCHOR_MM - pot.mount_error_mm(ANCHOR_MM)) / _slope(pot, x) for x in x_true])
    inside = (knots > 5) & (knots < 55)
    assert np.max(np.abs(gains[inside] / expected[inside] - 1)) < 0.004, np.c_[knots, gains, expected]
    assert abs(float(np.interp(ANCHOR_MM, knots, gains)) - 1) < 0.002
    assert stats["deformation_mm"] == pytest.approx(-0.45 * _slope(pot, ANCHOR_MM), rel=0.02)  # the friction cancelled
    if any(coeffs):
        assert stats["gain_range"][1] - stats["gain_range"][0] > 0.05  # a real slope to take out


def test_one_direction_alone_gives_no_bins():
    """Friction is cancelled only where both directions were swept."""
    d2, defl, direction = _sweep(_pot2([0.0] * 5))
    centres, means, counts = gain_sweep.direction_means(d2[direction > 0], defl[direction > 0], direction[direction > 0])
    assert len(centres) == 0


def test_a_sweep_that_misses_the_anchor_or_is_too_short_is_refused():
    d2, defl, direction = _sweep(_pot2([0.0] * 5))
    centres, means, counts = gain_sweep.direction_means(d2, defl, direction)
    with pytest.raises(UserError, match="did not pass the gauge's anchor"):
        gain_sweep.fit_gain(centres, means, counts, 70.0)
    with pytest.raises(UserError, match="at least"):
        gain_sweep.fit_gain(centres[:5], means[:5], counts[:5], float(centres[2]))


def test_what_df_left_is_taken_off_before_the_slope_is_read():
    """The no-load sweep's bin means are the offset table, and the weighted sweep's less them
    give the slope as if Df had left nothing: read without them, the same residual bends the gain
    by several %."""
    pot = _pot2([0.4, 1.1, 0.9, -0.3, 0.6])
    noload = _sweep(pot, d_true_mm=0.0, seed=4, residual=_residual)
    weighted = _sweep(pot, residual=_residual)
    offset_knots, offsets, knots, gains, stats = gain_sweep.offset_and_gain(noload, weighted, ANCHOR_MM)
    x_true = np.array([k - pot.mount_error_mm(k) for k in offset_knots])
    assert np.max(np.abs(offsets - _residual(x_true))[5:-5]) < 0.006  # a few um: noise and the 3-bin smoothing
    inside = (knots > 5) & (knots < 55)
    clean = gain_sweep.fit_gain(*gain_sweep.direction_means(*_sweep(pot)), ANCHOR_MM)[1]
    assert np.max(np.abs(gains / clean - 1)[inside]) < 0.005  # the two sweeps' noise
    raw = gain_sweep.fit_gain(*gain_sweep.direction_means(*weighted), ANCHOR_MM)[1]
    assert np.max(np.abs(raw / clean - 1)[inside]) > 0.015  # without the offset the residual reads as slope
    with pytest.raises(UserError, match="hardly deformed"):
        gain_sweep.offset_and_gain(noload, _sweep(pot, d_true_mm=0.0, seed=5, residual=_residual), ANCHOR_MM)
