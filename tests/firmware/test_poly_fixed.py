"""Polynomials in integer arithmetic (Horner, per-step exponents): Df_hat, F0(d) and d(F0) from
the paper's section 3-4, random polynomials, the 31-bit bound, and bit-identical MicroPython results."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware import poly_fixed
from firmware.poly_fixed import poly
from host.calibration.fixed_export import export_poly
from host.calibration.tracked_int import track
from testkit.interpreters import evaluate_on_micropython

DF = [-1.922222e-6, 2.632e-4, -1.63e-2, 0.46, -4.6]  # Df_hat(D1), mm -> mm (the paper's eq. 6)
F0 = [0.65, 12.37, 2.08]  # F0(d), mm -> N (the paper's eq. 8)
D_OF_F = [0.00091, 0.070, -0.18]  # d(F0), N -> mm (the paper's eq. 9)
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


# --- the board's proof that a polynomial stays within 31 bits (poly_fixed.overflow) ---

# Every word is within the layout's 2**29 limits, yet R_1 = 2**28 u / 2**8 reaches 2**35 over
# +-30 mm: the range checks alone accepted it, and the evaluation needs about 43 bits.
WIDE = [2, 0, -30000, 30000, 0, 2**28, 8, 0, 8, 0]


def test_board_refuses_a_polynomial_whose_words_pass_but_whose_evaluation_overflows():
    assert all(-(2**29) <= v < 2**29 for v in WIDE)
    assert track(poly, [-30000, 0, 30000], WIDE) > 2**40  # the refusal is deserved
    assert "31 bits" in poly_fixed.invalid(WIDE)


def test_board_refuses_a_polynomial_whose_final_rounding_overflows():
    # R_1 = 2**20 passes the multiplication bound, but R_0 = 2**29 - 1 + 2**20 u / 2**8 reaches
    # about 2**29 + 2**21, and rounding by 2**30 then adds 2**29
    k = [1, 500, 0, 1000, 30, 2**20, 8, 2**29 - 1]
    assert track(poly, [0, 1000], k) > 2**30
    assert "output can exceed 31 bits" in poly_fixed.invalid(k)


def _word():
    """A coefficient of random size: |A| below 2**b for b in 0..28."""
    return st.integers(0, 28).flatmap(lambda b: st.integers(-(2 << b) + 1, (2 << b) - 1))


def random_layouts():
    """Poly layouts with random words inside the range limits: some provable, most not."""
    return st.integers(0, 5).flatmap(
        lambda n: st.builds(
            layout,
            st.just(n),
            st.integers(-(2**18), 2**18),  # XC
            st.one_of(st.integers(0, 70000), st.integers(0, 2**21)),  # span of the input range
            st.integers(0, 30),  # E0
            st.lists(st.integers(8, 30), min_size=n, max_size=n),  # SH_j
            st.lists(_word(), min_size=n + 1, max_size=n + 1),  # A_N, then A_(N-1) .. A_0
        )
    )


def layout(n, xc, span, e0, shifts, a):
    k = [n, xc, xc - span // 2, xc - span // 2 + span, e0, a[0]]
    for j in range(n):
        k += [shifts[j], a[j + 1]]
    return k


def at_the_edge(k):
    """`k` with every A_j scaled by the largest factor the proof still accepts (bisection on
    log2 of the factor), or None: the layouts where an unsound proof would show."""
    def scaled(f):
        return k[:5] + [v if i % 2 else int(v * f) for i, v in enumerate(k[5:])]  # A_N, SH, A, SH, A..

    lo, hi = -40.0, 40.0
    if poly_fixed.invalid(scaled(2.0**lo)) is not None:
        return None
    for _ in range(40):
        mid = (lo + hi) / 2
        if poly_fixed.invalid(scaled(2.0**mid)) is None:
            lo = mid
        else:
            hi = mid
    return scaled(2.0**lo)


def accumulator(x, k, j):
    """R_j at input x, from the real evaluator run on the layout cut after accumulator j
    (output shift 0: poly then returns R_j itself, in exact CPython integers)."""
    n = k[0]
    return poly(x, [n - j, k[1], k[2], k[3], 0] + k[5 : 6 + 2 * (n - j)])


@settings(max_examples=150, deadline=None)
@given(random_layouts())
def test_a_polynomial_the_proof_accepts_keeps_the_bounds_it_claims(k):
    """Soundness, at the edge: scale a random layout up to the largest the proof accepts, then
    check at 401 inputs (and the ends) the bounds the proof claims: |R_j| * max(256, |uh|) <= 2**29
    before each multiplication and the final rounding below 2**30."""
    k = at_the_edge(k)
    if k is None:
        return
    n, xc, lo, hi, e0 = k[:5]
    for x in sorted(set(np.linspace(lo, hi, 401).round().astype(int).tolist()) | {lo, hi}):
        mult = max(256, abs((x - xc) >> 8))
        for j in range(1, n + 1):
            assert abs(accumulator(x, k, j)) * mult <= 2**29, (x, j, k)
        assert abs(accumulator(x, k, 0)) + ((1 << e0) >> 1) < 2**30, (x, k)
    probes = np.linspace(lo, hi, 41).round().astype(int).tolist()
    assert track(poly, probes, k) <= 2**30  # and so every intermediate of the real evaluator


def test_the_proof_accepts_a_useful_share_of_random_layouts():
    """The soundness test above is only worth something if the proof accepts some layouts."""
    from hypothesis import find

    k = find(random_layouts(), lambda k: k[0] >= 3 and poly_fixed.invalid(k) is None)
    assert k[0] >= 3 and poly_fixed.overflow(k) is None


def test_every_exported_polynomial_passes_the_boards_proof():
    rng = np.random.default_rng(11)
    for _ in range(40):
        x = np.linspace(0, 60, 200)
        y = rng.uniform(-5, 5) * np.sin(x / rng.uniform(5, 30) + rng.uniform(0, 3))
        k = export_poly(np.polyfit(x, y, int(rng.integers(1, 9))), 0, 60, 1000, 1000)
        assert poly_fixed.invalid(list(k)) is None


def test_the_proof_gives_the_same_answers_under_micropython():
    from testkit.interpreters import PREFER_EXTRA_PATHS, run_micropython

    rng = np.random.default_rng(3)
    cases = [WIDE] + [list(map(int, export_poly(c, lo, hi, i, o))) for c, (lo, hi), i, o in SPEC_CASES]
    for _ in range(30):  # random words near the edge: both answers occur
        n = int(rng.integers(1, 5))
        k = [n, 0, -int(rng.integers(1, 60000)), int(rng.integers(1, 60000)), int(rng.integers(0, 31)), int(rng.integers(-(2**20), 2**20))]
        for _ in range(n):
            k += [int(rng.integers(8, 31)), int(rng.integers(-(2**28), 2**28))]
        cases.append(k)
    expected = [poly_fixed.invalid(k) for k in cases]
    assert None in expected and any(e is not None for e in expected)
    source = PREFER_EXTRA_PATHS + "from firmware.poly_fixed import invalid\nfor k in %r:\n    print(repr(invalid(k)))\n" % cases
    out = run_micropython(source).stdout.splitlines()
    assert out == [repr(e) for e in expected]
