"""Piecewise-linear tables in integer arithmetic: exact knots, accuracy at every code, segment
splitting for 31 bits, dense tables of any curve, and bit-identical results under MicroPython."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware.pwl_fixed import pwl
from host.calibration.fixed_export import bcm_float, export_curve_table, export_pwl
from testkit.interpreters import evaluate_on_micropython

CODES = np.arange(4096)


def tables():
    """Knot codes strictly increasing anywhere in the ADC range, values in -3..63 mm."""

    def build(n, gaps, start, ys):
        xs = start + np.cumsum(np.asarray(gaps[:n]))
        return [float(x) for x in xs if x <= 4095], ys[:n]

    return st.builds(
        build,
        st.integers(2, 12),
        st.lists(st.floats(0.25, 600), min_size=12, max_size=12),
        st.floats(0, 200),
        st.lists(st.floats(-3, 63), min_size=12, max_size=12),
    ).filter(lambda t: len(t[0]) >= 2).map(lambda t: (t[0], t[1][: len(t[0])]))


@settings(max_examples=25, deadline=None)
@given(tables())
def test_table_matches_float_interpolation_at_every_code(table):
    xs, ys = table
    k = export_pwl(xs, ys, 12, max_error_um=1e9)
    got = np.array([pwl(int(c), k) for c in CODES], dtype=float)
    reference = np.interp(CODES, xs, np.asarray(ys) * 1000)
    # knot codes are kept to 1/16 code, values to 1 um, results rounded to 1 um
    slope = np.max(np.abs(np.diff(ys) / np.diff(xs))) * 1000 if len(xs) > 1 else 0
    assert np.max(np.abs(got - reference)) <= 1.0 + slope / 32 + 1e-9
    assert k.max_intermediate <= 2**30
    n = k[0]
    x_knots, y_knots = k[2 : 2 + n], k[2 + n :]
    assert all(b > a for a, b in zip(x_knots, x_knots[1:]))
    for i in range(n - 1):  # the 31-bit product bound the firmware relies on
        assert (x_knots[i + 1] - x_knots[i]) * abs(y_knots[i + 1] - y_knots[i]) <= 2**30 - 2**15


def test_knots_are_exact_and_ends_clamp():
    k = export_pwl([100, 500, 3000, 3900], [0, 5, 55, 60], 12)
    assert [pwl(c, k) for c in (0, 100, 500, 3000, 3900, 4095)] == [0, 0, 5000, 55000, 60000, 60000]
    assert k.max_error <= 0.5


def test_long_segments_are_split_exactly_on_the_line():
    k = export_pwl([0, 4095], [0, 60], 12)
    assert k[0] > 2, "a 60 mm segment over the whole ADC range exceeds 2**30 and must be split"
    got = np.array([pwl(int(c), k) for c in CODES])
    assert np.max(np.abs(got - CODES * 60000 / 4095)) <= 1.0
    assert np.all(np.diff(got) >= 0)


def test_dense_table_of_a_degree_5_bcm():
    """Degree > 3 goes through a table: the smallest one that meets 0.5 LSB is chosen."""
    c = {"lx": 40.0, "rx": 4000.0, "weights": [1, 8, 30, 30, 8, 1], "handles": [0, 1, 20, 40, 59, 60]}
    k = export_curve_table(lambda x: bcm_float(c, x), 12, x_range=(40.0, 4040.0))
    got = np.array([pwl(int(x), k) for x in CODES], dtype=float)
    assert np.max(np.abs(got - bcm_float(c, CODES) * 1000)) <= 60000 / 4096 / 2
    assert k[0] <= 1025
    with pytest.raises(ValueError, match="monotone"):
        export_curve_table(lambda x: np.sin(np.asarray(x) / 300.0), 12, n_points=65)


def test_refuses_bad_tables():
    with pytest.raises(ValueError, match="increasing"):
        export_pwl([0, 10, 10, 20], [0, 1, 2, 3], 12)
    with pytest.raises(ValueError, match="at least 2"):
        export_pwl([5], [1], 12)
    with pytest.raises(ValueError, match="distinct"):
        export_pwl([0, 0.01, 20], [0, 1, 2], 12)


def test_cpython_and_micropython_agree_on_many_tables():
    rng = np.random.default_rng(3)
    cases = [export_pwl([100, 500, 3000, 3900], [0, 5, 55, 60], 12), export_pwl([0, 4095], [0, 60], 12)]
    while len(cases) < 10:
        n = int(rng.integers(2, 20))
        xs = np.sort(rng.choice(np.arange(0, 4096 * 4), size=n, replace=False)) / 4.0
        cases.append(export_pwl(xs, rng.uniform(-3, 63, n), 12, max_error_um=1e9))
    inputs = list(range(-20, 4116))
    expected = [[pwl(x, list(k)) for x in inputs] for k in cases]
    assert evaluate_on_micropython("pwl_fixed", "pwl", cases, inputs) == expected
