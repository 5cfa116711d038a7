"""Piecewise-linear tables in integer arithmetic: exact knots, accuracy at every code, segment
splitting for 31 bits, dense tables of any curve, and bit-identical results under MicroPython."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware.pwl_fixed import pwl
from host.calibration.fixed_export import bcm_float, export_curve_table, export_pot, export_pwl
from host.errors import UserError
from host.fitting.piecewise_linear import _result as pwl_result
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
        assert (x_knots[i + 1] - x_knots[i]) * abs(y_knots[i + 1] - y_knots[i]) <= SEGMENT_LIMIT


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


from firmware.calibration import SEGMENT_LIMIT  # noqa: E402  (the product bound of every segment, check_pwl)


@st.composite
def tables_near_the_limits(draw):
    """(pwl words, inputs, which limit is crossed or None): tables a calibration file may hold,
    whoever wrote it, with segments at the product bound, values at +-2**29 and knots at the
    ends of the code range; in half of them one limit crossed (a segment one past the bound, a
    value at 2**29, a knot past 2**16, a repeated knot, a shift past 16)."""
    past = draw(st.sampled_from([None] * 5 + ["segment", "value", "knot", "repeat", "shift"]))
    shift = 17 if past == "shift" else draw(st.one_of(st.just(0), st.just(16), st.integers(0, 16)))
    n = draw(st.integers(2, 16))
    top = 1 << 16
    xs = sorted(draw(st.sets(st.integers(0, top), min_size=n, max_size=n)))
    if draw(st.booleans()):
        xs[0], xs[-1] = 0, top
    if past == "knot":
        xs[-1] = top + draw(st.integers(1, 1000))
    if past == "repeat":
        xs[1] = xs[0]
    y = [draw(st.one_of(st.just(-(2**29)), st.just(2**29 - 1), st.integers(-(2**29), 2**29 - 1)))]
    bad = draw(st.integers(0, n - 2))
    for i in range(1, n):
        dx = max(xs[i] - xs[i - 1], 1)
        most = SEGMENT_LIMIT // dx
        dy = draw(st.one_of(st.just(most), st.integers(0, most)))
        if past == "segment" and i - 1 == bad:
            dy = most + 1
        step = dy if y[-1] + dy < 2**29 else -dy
        if not -(2**29) <= y[-1] + step < 2**29:
            step = 0 if past != "segment" or i - 1 != bad else step
        y.append(y[-1] + step)
    if past == "value":
        y[draw(st.integers(0, n - 1))] = draw(st.sampled_from([2**29, -(2**29) - 1]))
    k = [n, shift] + xs + y
    last = (1 << max(0, 16 - shift)) - 1
    codes = {0, last} | {min(max((x >> shift) + d, 0), last) for x in xs for d in (-1, 0, 1)}
    codes |= set(draw(st.lists(st.integers(0, last), min_size=20, max_size=20)))
    return k, sorted(codes), past


@settings(max_examples=300, deadline=None)
@given(tables_near_the_limits())
def test_the_board_accepts_exactly_the_tables_that_stay_within_31_bits(table):
    """The board proves a pwl table safe from its words alone (firmware.calibration.check_pwl):
    a table past any limit is refused, and on any table it accepts every intermediate of the
    real evaluator, at every knot and random codes, stays within 2**30."""
    from firmware.calibration import CalibrationError, check_pwl
    from host.calibration.tracked_int import track

    k, codes, past = table
    try:
        check_pwl(k)
        accepted = True
    except CalibrationError:
        accepted = False
    if past is not None:
        assert not accepted, ("accepted past a limit", past, k)
        return
    assert accepted, k
    assert track(pwl, codes, k) <= 2**30, k



def test_a_pot_curve_whose_integer_form_falls_is_never_exported():
    """The firmware refuses at boot a pot curve whose integer positions fall at any code; asked
    for a rising curve (as pot_section asks by default) the exporter never gives one. These knots rise at every integer code in float,
    but the knot at 2001.02 lands on code 2001 at the table's 1/16-code resolution, so the
    table as such falls there; the exporter takes a table sampled from the curve instead. A
    curve that really falls is refused with the reason (`calibrate` reports it, writes nothing)."""
    from host.calibration.file import pot_section
    from host.fitting.fit_result import is_monotone

    knots_x = [0.0, 2000.0, 2000.5, 2001.02, 4095.0]
    hidden = pwl_result("pwl", 5, 8, knots_x, [0.0, 30.0, 30.03, 29.999, 60.0])
    assert is_monotone(hidden, CODES.astype(float))
    as_is = export_pwl(knots_x, hidden.coefficients["knots_y"], 12)
    assert as_is.outputs[2001] < as_is.outputs[2000]  # the case is real
    assert export_pot(hidden, 12)[1] == as_is  # written as is only when asked for any curve
    kind, k = export_pot(hidden, 12, rising=True)
    assert kind == "pwl" and np.all(np.diff([pwl(c, k) for c in CODES]) >= 0)
    assert k.max_error <= k.bound
    falling = pwl_result("pwl", 4, 6, [0.0, 2000.0, 2010.0, 4095.0], [0.0, 30.0, 29.9, 60.0])
    with pytest.raises(ValueError, match="falls at code|not monotone"):
        export_pot(falling, 12, rising=True)
    with pytest.raises(UserError, match="cannot export"):
        pot_section(falling, 12)


def test_knots_a_fit_put_on_one_code_with_one_value_are_merged_not_refused():
    """A free-knot fit of 29-33 knots put two knots at one code (and two within 1/16 code) with the
    same value on real sweeps (stop 58); refused, the pot curve fell back to a code-by-code table
    of about 50 KB, and the calibration file passed the 64 KiB a board reads. Merged, the table is
    the same curve and stays small; knots at one code with different values are still refused."""
    xs = [0.0, 1000.0, 2000.0, 2000.0, 3000.0, 4094.97, 4095.0]
    ys = [0.0, 15.0, 30.0, 30.0, 45.0, 60.0, 60.0]
    k = export_pwl(xs, ys, 12)
    assert k[0] <= 8  # 5 knots, and the long segments split
    got = np.array([pwl(int(c), k) for c in CODES])
    assert np.max(np.abs(got - np.interp(CODES, [0, 1000, 2000, 3000, 4095], [0, 15000, 30000, 45000, 60000]))) <= 1
    with pytest.raises(ValueError, match="increasing"):
        export_pwl([0, 10, 10, 20], [0, 1, 2, 3], 12)
