"""The assembly error Df: a polynomial in D1 where one follows it, a free-knot table where the
pots' own tables leave kinks in D1 - D2; and the board evaluates a Df table as the host does."""

from pathlib import Path

import numpy as np

from firmware.pwl_fixed import DF_PWL_OFFSET, df_table_input, pwl
from host.calibration.file import force_table_section
from host.fitting.assembly import binned_peak, choose_order, df_table, fit_df, near_the_stops
from testkit.interpreters import on_cpython, on_micropython
from testkit.model import write_model_calibration

DATA = Path(__file__).resolve().parents[1] / "data"


def _sweep(kinks, seed=4):
    rng = np.random.default_rng(seed)
    x = np.sort(rng.uniform(0.0, 60.0, 2500))
    v = (x - 30.0) / 30.0
    df = 0.4 * v**4 + 0.1 * v - 0.2 * v**2  # a mounting error, smooth in the position
    for at, slope in kinks:  # what a pot table's knots leave: changes of slope
        df += slope * np.abs(x - at)
    return x, df + rng.normal(0.0, 0.06, len(x))


def test_samples_held_at_an_end_stop_are_not_fitted():
    """A sweep that ends against each stop: the block is held while the nut runs 0.6 mm on into
    the spring, so D1 - D2 there is the spring's deformation. Fitted with those samples, Df
    chases them (a higher order, bin means off by more than the target's 0.1 mm); without them
    it is the mounting error's quartic again."""
    x, df = _sweep([])
    d2 = x - df
    held = np.linspace(0.0, 0.6, 60)  # the spring's deformation while the stop holds the block
    x_all = np.concatenate([x.min() - held, x, x.max() + held])
    d2_all = np.concatenate([np.full(60, d2.min() - 0.05), d2, np.full(60, d2.max() + 0.05)])
    df_all = x_all - d2_all
    _, resid, order, _ = fit_df(x_all, df_all, "auto")
    assert binned_peak(x_all, resid) > 0.1, (order, binned_peak(x_all, resid))
    near = near_the_stops(d2_all * 1000.0)
    assert np.all(near[:60]) and np.all(near[-60:])
    assert np.count_nonzero(near[60:-60]) < 0.02 * len(x)  # the sweep itself keeps its samples
    _, resid, order, _ = fit_df(x_all[~near], df_all[~near], "auto")
    assert order == 4 and binned_peak(x_all[~near], resid) < 0.03, (order, binned_peak(x_all[~near], resid))


def test_a_smooth_df_keeps_its_polynomial():
    x, df = _sweep([])
    _, scores = choose_order(x, df, "auto", floor=4)
    assert df_table(x, df) is None


def test_a_df_that_no_polynomial_follows_gets_a_table():
    """A no-load assembly sweep recorded from a random simulated actuator (bench_robustness seed
    1002: noisy pots, mounting error on both, free-knot pot tables): the polynomial's hold-out
    error still falls at order 12 and order 10 leaves 0.13 mm of 1 mm bin means; a 6-knot table
    reaches the noise (the target is 0.1 mm)."""
    x, df = np.loadtxt(DATA / "assembly-sweep-seed1002.csv", delimiter=",", unpack=True)
    order, scores = choose_order(x, df, "auto", floor=4)
    table = df_table(x, df)
    assert table is not None
    kx, ky, _ = table
    poly_peak = binned_peak(x, df - np.polyval(np.polyfit(x, df, min(order, 10)), x))
    table_peak = binned_peak(x, df - np.interp(x, kx, ky))
    assert table_peak < 0.1 < poly_peak, (table_peak, poly_peak)


def test_the_board_subtracts_a_df_table_as_the_host_computes_it(tmp_path):
    kx = np.array([0.0, 10.0, 25.0, 40.0, 60.0])
    ky = np.array([1.2, 0.3, -0.1, 0.2, 1.0])
    section = force_table_section(kx, ky, (-1.0, 61.0), ("um", "um"), df=True)
    path = tmp_path / "cal.json"
    write_model_calibration(path, df=section)
    codes = list(range(0, 4096, 97))
    call = "case_df_table(%r, %r)" % (str(path), codes)
    here = on_cpython("tests.firmware.app_cases", call)
    assert here == on_micropython("tests.firmware.app_cases", call)
    for d1_star, d1 in here:
        expected = d1 - pwl(df_table_input(d1), section["fixed"])
        assert d1_star == max(-65535, min(65535, expected))
        assert abs((d1 - d1_star) / 1000.0 - np.interp(d1 / 1000.0, kx, ky)) < 0.002 or not -1000 <= d1 <= 61000


def test_a_df_table_holds_the_whole_range_pot_1_can_read():
    """Pot 1's mounting error puts D1 anywhere from about -5 to 65 mm (boards/sim.json's runs
    4.6-63.7 mm): a Df table's input, D1 in 2 um units about DF_PWL_OFFSET, holds it all."""
    from firmware import measurement

    assert measurement._DF_PWL_OFFSET == DF_PWL_OFFSET  # the step's inlined copy
    for lo, hi in ((4.6, 63.7), (-5.0, 65.0)):
        kx = np.linspace(lo, hi, 8)
        section = force_table_section(kx, 0.01 * kx, (lo, hi), ("um", "um"), df=True)
        for d1 in (lo, (lo + hi) / 2, hi):
            assert abs(pwl(df_table_input(int(d1 * 1000)), section["fixed"]) - 10 * d1) <= 1.5
