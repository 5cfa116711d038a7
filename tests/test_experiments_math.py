"""The pieces of the experiments and guided fits that need no board: the nominal 2-point pot
calibration, the Df order choice by cross-validation, the force hysteresis measure."""

import numpy as np

from firmware.calibration import convert, pot_constants
from host.experiments.variants import nominal_pot_section
from host.guided.assembly_calibration import choose_order, fit_df
from host.guided.force_calibration import hysteresis_n


def test_nominal_pot_is_the_line_through_the_end_readings():
    raw = np.linspace(300, 3900, 500)
    ref = 60 * ((raw - 300) / 3600) ** 1.3  # a bent pot
    section = nominal_pot_section(raw, ref, 12, "pot2")
    kind, k = pot_constants(section, "pot2")
    assert kind == "pwl"
    for code, want_um in ((300, 0.0), (2100, 30000.0), (3900, 60000.0)):
        assert abs(convert(kind, code, k) - want_um) <= 10  # straight line, not the bent curve


def test_df_order_by_cross_validation_finds_the_true_degree():
    rng = np.random.default_rng(2)
    x = np.sort(rng.uniform(0, 60, 2000))
    v = (x - 30) / 30
    df = 4.6 * v**4 - 0.5 * v**3 + 0.1 * v + rng.normal(0, 0.02, x.size)
    order, scores = choose_order(x, df, "auto")
    assert order == 4
    assert scores[3] > 2 * scores[4]
    coeffs, resid, used, _ = fit_df(x, df, 4)
    assert used == 4 and np.max(np.abs(resid)) < 0.1


def test_force_hysteresis_is_the_gap_between_loading_and_unloading():
    d = np.tile(np.linspace(-1.4, -0.2, 8), 2)
    loading = np.repeat([True, False], 8)
    f = 12.4 * d + np.where(loading, -0.3, 0.3)  # friction opposes the motion each way
    assert abs(hysteresis_n(d, f, loading, 2) - 0.6) < 1e-6
    assert np.isnan(hysteresis_n(d[:3], f[:3], loading[:3], 2))
