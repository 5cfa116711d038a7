"""The held-out figures' draws and the direction-balanced Df (host/experiments/held_out.py)."""

import numpy as np

from host.experiments import held_out
from host.experiments.displacement import TARGETS_MM
from host.experiments.force_runs import STEPS_N


def test_drawn_forces_keep_away_from_everything_a_calibration_step_held():
    held = [4.8, 9.6, 14.4]
    levels = [2.1, 4.3, 6.5, 8.6, 10.8, 12.9, 15.1, 16.7, 2.3, 4.1, 6.6, 8.8, 10.6, 13.0, 14.9]
    for seed in range(40):
        drawn = held_out.draw_forces(np.random.default_rng(seed), 16.7, held, levels)
        assert len(drawn) == 6, (seed, drawn)
        up, down = drawn[:3], drawn[3:]
        assert up == sorted(up) and down == sorted(down, reverse=True) and max(down) < max(up)  # loading, then unloading
        for v in drawn:
            assert 0.15 * 16.7 <= v <= 0.9 * 16.7
            assert all(abs(v - h) >= held_out.FORCE_GAP_N for h in held + list(STEPS_N))
            assert all(abs(v - lv) >= held_out.LEVEL_GAP_N for lv in levels)
        assert len(set(drawn)) == 6


def test_draws_repeat_with_their_seed_and_differ_between_seeds():
    one = held_out.draw_forces(np.random.default_rng(7), 16.0, [4.8, 9.6, 14.4])
    assert one == held_out.draw_forces(np.random.default_rng(7), 16.0, [4.8, 9.6, 14.4])
    assert one != held_out.draw_forces(np.random.default_rng(8), 16.0, [4.8, 9.6, 14.4])


def test_drawn_positions_are_inside_the_stroke_and_off_the_papers_targets():
    drawn = held_out.draw_positions(np.random.default_rng(3), (0.5, 59.5))
    assert len(drawn) == held_out.POSITIONS and drawn == sorted(drawn)
    assert all(1.0 <= t <= 59.0 and min(abs(t - p) for p in TARGETS_MM) >= held_out.POSITION_GAP_MM for t in drawn)


def test_the_friction_deflection_cancels_between_directions_and_the_assembly_error_stays():
    """A sweep with 3x more samples forward than backward: pooled bin means carry the friction's
    deflection (+-0.1 mm, a soft spring and a sticky block), the balanced ones only the Df left."""
    rng = np.random.default_rng(1)
    x = np.concatenate([np.linspace(1, 59, 3000), np.linspace(59, 1, 1000)])
    direction = np.concatenate([np.ones(3000), -np.ones(1000)])
    left = 0.03 * np.sin(x / 7.0)  # the Df the calibration did not take out
    resid = left + 0.1 * direction + rng.normal(0, 0.01, len(x))
    balanced, pooled, deflection = held_out.direction_balanced_peak(x, resid, direction)
    assert abs(balanced - 0.03) < 0.01
    assert pooled > 0.07  # the deflection's net share, which has nothing to do with Df
    assert abs(deflection - 0.1) < 0.005


def test_the_force_steps_elsewhere_hook_the_gauge_at_mid_stroke_or_a_quarter_stroke_off():
    """Mid stroke (where the paper ran Table 1) unless the anchor sits within 5 mm of it; then a
    quarter of the stroke away from the anchor, toward the end with room."""
    assert held_out.away_anchor_mm((0.0, 60.0), 45.0) == 30.0
    assert held_out.away_anchor_mm((-22.0, 58.0), 38.0) == 18.0
    assert held_out.away_anchor_mm((0.0, 60.0), 32.0) == 17.0
    assert held_out.away_anchor_mm((0.0, 60.0), 27.0) == 42.0
    for stroke, anchor in (((0.0, 60.0), 45.0), ((0.0, 60.0), 30.0), ((10.0, 55.0), 34.0)):
        away = held_out.away_anchor_mm(stroke, anchor)
        assert abs(away - anchor) >= held_out.MIN_AWAY_MM and stroke[0] < away < stroke[1]


def test_the_validation_sweep_reports_the_firmware_deformation_beside_d1_star_less_d2(monkeypatch):
    """The firmware takes the gain step's offset table off D1* - D2 (telemetry defl_um); the held-out
    Df is the paper's D1* - D2, and the deformation the force estimate starts from is reported
    beside it, each from its own column."""
    from host.guided import acquire

    x = np.concatenate([np.linspace(2, 58, 2000), np.linspace(58, 2, 2000)])
    direction = np.concatenate([np.ones(2000), -np.ones(2000)])
    left = 0.03 * np.sin(x / 7.0)  # what Df left (mm); the offset table takes all but 0.005 of it
    records = np.zeros((len(x), len(acquire.COL)), dtype=np.int64)
    records[:, acquire.COL["d2_um"]] = np.round(1000 * x)
    records[:, acquire.COL["d1_um"]] = np.round(1000 * (x + left))
    records[:, acquire.COL["defl_um"]] = np.round(1000 * 0.005 * np.cos(x / 5.0))
    monkeypatch.setattr(acquire, "sweep", lambda client, duty, say=None: (records, direction))

    class Rig:
        def no_load(self):
            pass

    class Session:
        client = None

    df = held_out.df_validation(Session(), Rig(), 1200, say=lambda *a: None)
    assert abs(df["peak_binned_mm"] - 0.03) < 0.003
    assert abs(df["peak_deformation_mm"] - 0.005) < 0.0015
