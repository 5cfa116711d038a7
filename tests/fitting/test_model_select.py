"""--model auto picks the cheapest firmware model that reaches the floor, else the best in budget."""

import numpy as np

from host.fitting.model_select import candidates, select_model
from host.fitting.noise_floor import curve_floor
from host.fitting.rational_bezier import evaluate
from host.fitting.sweep import load_sweep
from host.fitting.example_sweep import DEFAULT_PATH


def test_candidates_are_firmware_models_cheapest_first():
    c = candidates(12)
    assert [n for n, _, _ in c] == sorted(n for n, _, _ in c)
    assert all(model in ("bcm", "pwl") and n <= 12 for n, model, _ in c)
    assert ("bcm", 3) in [(m, o) for _, m, o in c] and ("bcm", 4) not in [(m, o) for _, m, o in c]
    assert all(n <= 6 for n, _, _ in candidates(6))


def test_straight_line_data_gets_the_cheapest_model():
    rng = np.random.default_rng(5)
    x = np.sort(rng.uniform(0, 4095, 800)).round()
    y = x * 60 / 4095 + rng.normal(0, 0.02, x.size)
    sel = select_model(x, y, noise=0.02)
    assert sel.result.n_params == min(n for n, _, _ in candidates())
    assert "cheapest" in sel.reason and len(sel.tried) == 1


def test_bcm_curve_is_matched_by_a_bcm_when_that_is_cheapest():
    x = np.arange(0, 4096, 2.0)
    coeffs = {"lx": 0.0, "rx": 4094.0, "weights": [1.0, 8.0, 8.0, 1.0], "handles": [0.0, 4.0, 56.0, 60.0]}
    rng = np.random.default_rng(6)
    y = evaluate(coeffs, x) + rng.normal(0, 0.01, x.size)
    sel = select_model(x, y, noise=0.01)
    assert sel.result.rms <= 1.1 * 0.01
    cheaper = [t for t in sel.tried if t["n_params"] < sel.result.n_params]
    assert all(t["rms"] > 1.1 * 0.01 for t in cheaper)  # it really is the cheapest that made it


def test_falls_back_to_best_within_budget():
    sweep = load_sweep(DEFAULT_PATH)
    sel = select_model(sweep.x, sweep.y, noise=0.001, budget=8)  # an unreachable floor
    assert "most accurate" in sel.reason
    assert sel.result.n_params <= 8
    assert sel.result.rms == min(t["rms"] for t in sel.tried)


def test_example_sweep_reaches_its_curve_floor():
    sweep = load_sweep(DEFAULT_PATH)
    floor = curve_floor(sweep.x, sweep.y, sweep.direction)
    sel = select_model(sweep.x, sweep.y, noise=floor)
    assert sel.result.rms <= 1.1 * floor and sel.result.monotone
