"""Polynomials in integer arithmetic (Horner, per-step exponents): Df_hat, F0(d) and d(F0) from
SPEC section 3-4, random polynomials, the 31-bit bound, and bit-identical MicroPython results."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware.poly_fixed import poly
from host.fixed_export import export_poly, track
from test_fixed_on_micropython import evaluate_on_micropython

DF = [-1.922222e-6, 2.632e-4, -1.63e-2, 0.46, -4.6]  # Df_hat(D1), mm -> mm (SPEC eq. 6)
F0 = [0.65, 12.37, 2.08]  # F0(d), mm -> N (SPEC eq. 8)
D_OF_F = [0.00091, 0.070, -0.18]  # d(F0), N -> mm (SPEC eq. 9)
SPEC_CASES = [  # (coefficients, x range in natural units, in_scale, out_scale)
    (DF, (0.0, 60.0), 1000, 1000),  # um -> um
    (F0, (-2.0, 6.0), 1000, 1000),  # um -> mN
    (D_OF_F, (-20.0, 80.0), 1000, 1000),  # mN -> um
]


def all_inputs(lo, hi, scale):
    return np.arange(int(np.ceil(lo * scale)), int(np.floor(hi * scale)) + 1)


@pytest.mark.parametrize("coeffs, x_range, in_scale, out_scale", SPEC_CASES)
def test_spec_polynomials_within_one_unit_at_every_input(coeffs, x_range, in_scale, out_scale):
    k = export_poly(coeffs, *x_range, in_scale, out_scale)
    x = all_inputs(*x_range, in_scale)
    got = np.array([poly(int(v), k) for v in x[::3]], dtype=float)
    reference = np.polyval(coeffs, x[::3] / in_scale) * out_scale
    err = np.max(np.abs(got - reference))
    assert err <= 1.0  # 1 um or 1 mN: the final rounding (0.5) plus the Horner steps
    assert k.max_error <= 1.0 and k.max_intermediate <= 2**30


def test_df_values_match_the_paper_shape():
    k = export_poly(DF, 0.0, 60.0, 1000, 1000)
    assert poly(0, k) == -4600
    assert abs(poly(30000, k)) < 300  # the pots agree at mid-stroke
    assert poly(-5000, k) == poly(0, k) and poly(70000, k) == poly(60000, k)  # clamped


def polynomials():
    return st.tuples(
        st.lists(st.floats(-1, 1), min_size=1, max_size=6),  # coefficients on x in [-1, 1] units
        st.floats(1, 100),  # output scale: peak roughly 1..100 natural units
    )


@settings(max_examples=25, deadline=None)
@given(polynomials())
def test_random_polynomials(case):
    coeffs, peak = case
    a = np.array(coeffs) * peak
    k = export_poly(a, -1.0, 1.0, 8000, 1000)  # inputs -8000..8000, outputs in thousandths
    x = all_inputs(-1.0, 1.0, 8000)
    got = np.array([poly(int(v), k) for v in x[::7]], dtype=float)
    reference = np.polyval(a, x / 8000) * 1000
    assert np.max(np.abs(got - reference[::7])) <= max(1.0, 2.0**-13 * np.max(np.abs(reference)))
    assert track(poly, x[::7], k) <= 2**30


def test_refuses_outputs_beyond_31_bits():
    with pytest.raises(ValueError, match="2\\*\\*29"):
        export_poly([1e6, 0, 0], -60, 60, 1000, 1000)


def test_cpython_and_micropython_agree():
    rng = np.random.default_rng(5)
    cases = [export_poly(c, lo, hi, i, o) for c, (lo, hi), i, o in SPEC_CASES]
    for _ in range(6):
        cases.append(export_poly(rng.uniform(-1, 1, int(rng.integers(1, 7))) * 50, -1.0, 1.0, 30000, 1000))
    inputs = list(range(-90000, 90001, 97))
    expected = [[poly(x, list(k)) for x in inputs] for k in cases]
    assert evaluate_on_micropython("poly_fixed", "poly", cases, inputs) == expected
