"""The data-only noise estimate recovers a known noise level."""

import numpy as np

from host.fitting.noise_floor import estimate_noise


def _knee(x):
    # a pot curve with two knees, in mm over 12-bit codes
    t = x / 4095.0
    return 60 * t + 2.0 * np.tanh((t - 0.1) / 0.03) - 2.5 * np.tanh((t - 0.85) / 0.04)


def test_recovers_known_noise_in_reference():
    rng = np.random.default_rng(1)
    x = np.sort(rng.uniform(0, 4095, 2000))
    for sigma in (0.005, 0.02, 0.1):
        y = _knee(x) + rng.normal(0, sigma, x.size)
        assert abs(estimate_noise(x, y) / sigma - 1) < 0.06


def test_noise_in_the_adc_codes_shows_in_reference_units():
    # the realistic case: the reading is noisy (1.5 LSB), the reference is exact
    rng = np.random.default_rng(2)
    truth = rng.uniform(0, 4095, 2000)
    x = np.round(truth + rng.normal(0, 1.5, truth.size))
    y = _knee(truth)
    order = np.argsort(x, kind="stable")
    x, y = x[order], y[order]
    true_floor = np.std(y - _knee(x))
    assert abs(estimate_noise(x, y) / true_floor - 1) < 0.1


def test_direction_split_removes_hysteresis():
    rng = np.random.default_rng(3)
    x = rng.uniform(0, 4095, 3000)
    d = np.where(rng.random(x.size) < 0.5, 1.0, -1.0)
    sigma = 0.01
    y = _knee(x) + 0.05 * d + rng.normal(0, sigma, x.size)  # 100 um between directions
    split = estimate_noise(x, y, d)
    merged = estimate_noise(x, y)
    assert abs(split / sigma - 1) < 0.06
    assert merged > 2 * sigma


def test_repeated_codes_are_handled():
    rng = np.random.default_rng(4)
    x = np.repeat(np.arange(0, 4096, 4.0), 3)
    y = _knee(x) + rng.normal(0, 0.03, x.size)
    assert abs(estimate_noise(x, y) / 0.03 - 1) < 0.06
