"""BCM-3 in integer arithmetic: accuracy against float64 at every ADC code, the 31-bit bound, the
exporter's refusals, and bit-identical results under the real MicroPython."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware.bcm_fixed import bcm3, invalid
from host.calibration.fixed_export import export_bcm3, export_pot
from host.calibration.tracked_int import TrackedInt, track
from host.fitting.models import fit_model
from host.fitting.sweep import load_sweep
from testkit.interpreters import evaluate_on_micropython

CODES = np.arange(4096)
HALF_LSB_60MM = 60000 / 4096 / 2  # 7.32421875 um: the bound for a 60 mm pot on a 12-bit ADC
KNEE = {"lx": 60.0, "rx": 3950.0, "weights": [1.0, 12.0, 12.0, 1.0], "handles": [0.0, 1.5, 58.5, 60.0]}


def rational_bernstein_um(c, x):
    """Reference written out for degree 3 (independent of the exporter's own evaluator)."""
    t = np.clip((np.asarray(x, dtype=float) - c["lx"]) / c["rx"], 0.0, 1.0)
    s = 1.0 - t
    b = [s**3, 3 * t * s**2, 3 * t**2 * s, t**3]
    w, p = c["weights"], c["handles"]
    num = sum(b[i] * w[i] * p[i] for i in range(4))
    den = sum(b[i] * w[i] for i in range(4))
    return 1000.0 * num / den


def integer_curve(k):
    return np.array([bcm3(int(c), k) for c in CODES], dtype=float)


def test_knee_curve_within_half_lsb_at_every_code():
    k = export_bcm3(KNEE, 12)
    err = np.max(np.abs(integer_curve(k) - rational_bernstein_um(KNEE, CODES)))
    assert err <= HALF_LSB_60MM
    assert k.bound == HALF_LSB_60MM and math.isclose(k.max_error, err)
    assert k.max_intermediate <= 2**30
    assert np.all(np.diff(integer_curve(k)) >= 0), "a monotone curve must stay monotone in integers"


def test_clamps_outside_the_calibrated_range():
    k = export_bcm3(KNEE, 12)
    assert bcm3(0, k) == bcm3(60, k) == 0
    assert bcm3(4095, k) == bcm3(4010, k) == 60000


def box_curves(realistic=True):
    """Curves the fitter can return: lx/ux near the rails, w_0 = 1 and every other weight in the
    fitter's box [1/60, 60] (so up to 3600 between two weights), interior handles anywhere in the
    widened reference range [-6, 66] mm, sorted or not. `realistic`: the curve is a pot's, its
    end handles (f at lx and ux) near the two ends of a 60 mm stroke, either way round; else the
    end handles are anywhere too, and the curve's span, hence its 0.5 LSB, can be tiny."""
    end = st.floats(-6, 12) if realistic else st.floats(-6, 66)
    far = st.floats(48, 66) if realistic else st.floats(-6, 66)
    return st.builds(
        lambda lx, ux, logw, p0, mid, p3, sort, flip: {
            "lx": lx,
            "rx": ux - lx,
            "weights": [1.0] + [60.0**v for v in logw],
            "handles": (lambda h: h[::-1] if flip else h)([p0, *(sorted(mid) if sort else mid), p3]),
        },
        st.floats(0, 400),
        st.floats(3600, 4095),
        st.lists(st.floats(-1, 1), min_size=3, max_size=3),
        end,
        st.lists(st.floats(-6, 66), min_size=2, max_size=2),
        far,
        st.booleans(),
        st.booleans(),
    )


def error_model(c):
    """What the integer form may be off (um): 0.5 for the output in whole um, plus 2**-14 of the
    handle spread (each term c_i u^i to ~2**-15 of itself, the Q16 shares; docs/fixed-point.md)."""
    return 1.0 + 1000 * (max(c["handles"]) - min(c["handles"])) / 2**14


@settings(max_examples=40, deadline=None)
@given(box_curves())
def test_every_pot_curve_in_the_fitters_box_is_within_half_an_lsb(c):
    """The steepest curves of the box rise by millimetres within one code next to an end; the
    float-like terms keep them within 0.5 LSB at every code anyway, with every intermediate
    within 2**30, so the exporter never has to refuse a pot curve (it would raise here)."""
    k = export_bcm3(c, 12)
    reference = rational_bernstein_um(c, CODES)
    err = np.max(np.abs(integer_curve(k) - reference))
    assert err <= 0.5 * (reference.max() - reference.min()) / 4096
    assert err <= error_model(c)
    assert k.max_intermediate <= 2**30


@settings(max_examples=20, deadline=None)
@given(box_curves(realistic=False))
def test_any_curve_in_the_box_keeps_the_error_model_and_31_bits(c):
    """Any handles: the error model and the 31 bits still hold, and the exporter refuses exactly
    the curves over 0.5 LSB (those with a span of a few mm, where 0.5 LSB is under 1 um)."""
    try:
        k = export_bcm3(c, 12)
        refused = False
    except ValueError as e:
        assert "bound" in str(e)
        k = export_bcm3(c, 12, max_error_um=1e9)
        refused = True
    reference = rational_bernstein_um(c, CODES)
    err = np.max(np.abs(integer_curve(k) - reference))
    assert err <= error_model(c)
    assert k.max_intermediate <= 2**30
    assert refused == (err > 0.5 * (reference.max() - reference.min()) / 4096)


def test_steep_curves_next_to_both_ends():
    """Weights 60 and 1/60 (a ratio of 3600) put a jump of tens of mm within about one code of an
    end; the fixed-point t of the previous layout was 30-150 um off there."""
    for w, p in (([1, 1 / 60, 60, 1 / 60], [0, 60, -6, 66]), ([1, 60, 1 / 60, 60], [66, 0, 60, -6]),
                 ([1, 60, 60, 1], [0, 60, 0, 60])):
        c = {"lx": 0.3, "rx": 4000.3, "weights": w, "handles": p}
        k = export_bcm3(c, 12)
        fine = rational_bernstein_um(c, np.linspace(0, 4095, 4095 * 16 + 1))
        assert np.max(np.abs(np.diff(fine))) * 16 > 1000  # over 1 mm per code somewhere
        assert k.max_error <= k.bound and k.max_intermediate <= 2**30


def test_cpython_and_micropython_agree_on_many_curves():
    rng = np.random.default_rng(7)
    cases = [export_bcm3(KNEE, 12)]
    while len(cases) < 12:
        lx, ux = rng.uniform(0, 400), rng.uniform(3600, 4095)
        w = [1.0, *(60.0 ** rng.uniform(-1, 1, 3))]  # the fitter's whole box
        c = {"lx": lx, "rx": ux - lx, "weights": w, "handles": list(rng.uniform(-6, 66, 4))}
        cases.append(export_bcm3(c, 12, max_error_um=1e9))
    inputs = list(range(-20, 4116))
    expected = [[bcm3(x, list(k)) for x in inputs] for k in cases]
    assert evaluate_on_micropython("bcm_fixed", "bcm3", cases, inputs) == expected


def test_refuses_what_it_cannot_represent():
    with pytest.raises(ValueError, match="degree 3"):
        export_bcm3({"lx": 0, "rx": 4095, "weights": [1] * 6, "handles": [0, 10, 20, 30, 40, 60]}, 12)
    with pytest.raises(ValueError, match="weight ratio"):  # 2**83: beyond the exponent range
        export_bcm3({"lx": 0, "rx": 4095, "weights": [1, 1e25, 1, 1], "handles": [0, 20, 40, 60]}, 12)
    with pytest.raises(ValueError, match="positive"):
        export_bcm3({"lx": 0, "rx": 4095, "weights": [1, -2, 1, 1], "handles": [0, 20, 40, 60]}, 12)
    with pytest.raises(ValueError, match="ADC range"):
        export_bcm3({"lx": 0, "rx": 40950, "weights": [1, 2, 2, 1], "handles": [0, 20, 40, 60]}, 12)
    with pytest.raises(ValueError, match="spread"):
        export_bcm3({"lx": 0, "rx": 4095, "weights": [1, 2, 2, 1], "handles": [0, 2000, 4000, 6000]}, 12)
    # the output is whole um: a bound under 0.5 um cannot be met
    with pytest.raises(ValueError, match="bound"):
        export_bcm3(KNEE, 12, max_error_um=0.4)


def test_layout_check_names_what_is_wrong():
    k = list(export_bcm3(KNEE, 12))
    assert invalid(k) is None
    for i, value, why in ((2, 100, "input scaling"), (3, k[3] + 1, "span shift"), (4, 9, "handle shift"),
                          (8, k[5] + 2**22, "handles"), (9, 2**17, "weight ratio"), (16, 65, "weight ratio")):
        bad = list(k)
        bad[i] = value
        assert why in invalid(bad)
    assert "21 values" in invalid(k[:-1])


def test_instrumentation_sees_an_overflow():
    """The tracked run is not a formality: constants outside the layout's limits are caught."""
    k = list(export_bcm3(KNEE, 12))
    k[8] = k[5] + 2**23  # a handle spread 4x the limit
    assert track(bcm3, range(0, 4096, 64), k) > 2**30
    assert TrackedInt(3) * 5 == 15 and isinstance(TrackedInt(3) * 5, TrackedInt)


def test_bcm3_fits_of_real_adc_curves(realdata_dir):
    """The four measured ADC curves (volts or codes against a reference), fitted by the project's
    BCM-3 fitter and read as a 60 mm pot (a pot is a voltage divider): each exports as bcm3
    within 0.5 LSB, within 31 bits, and runs bit-identically under MicroPython."""
    cases = []
    for path in sorted(realdata_dir.glob("*.csv")):
        sweep = load_sweep(path)
        fit = fit_model("bcm", sweep.x, sweep.y, 3)
        unit_um = 60000 / np.ptp(fit(CODES))
        kind, k = export_pot(fit, 12, unit_um=unit_um)
        assert kind == "bcm3", path.name
        got = integer_curve(k)
        assert np.max(np.abs(got - fit(CODES) * unit_um)) <= HALF_LSB_60MM + 1e-9, path.name
        assert k.max_intermediate <= 2**30
        cases.append(k)
    assert len(cases) == 4
    expected = [[bcm3(x, list(k)) for x in range(4096)] for k in cases]
    assert evaluate_on_micropython("bcm_fixed", "bcm3", cases, range(4096)) == expected


@st.composite
def layouts_near_the_limits(draw):
    """(bcm3 words, inputs, which limit is crossed or None): words at the layout's limits (a
    calibration file may come from anywhere, not only the exporter): spans, spreads, shifts,
    mantissas and exponents at their ends, and in half the layouts one of them past its limit,
    just or far; with the inputs where the evaluation turns: both ends of the curve, its
    middle (a = b), the ends of the input range and random codes."""
    past = draw(st.sampled_from([None] * 14 + list(range(14))))
    field = iter(range(14))

    def near(lo, hi, far_lo, far_hi):  # within [lo, hi], often at an end; past it for the chosen field
        if next(field) == past:
            beyond = [st.just(hi + 1), st.integers(hi + 1, far_hi)]
            if far_lo < lo:
                beyond += [st.just(lo - 1), st.integers(far_lo, lo - 1)]
            return draw(st.one_of(*beyond))
        return draw(st.one_of(st.just(lo), st.just(hi), st.integers(lo, hi)))

    s = draw(st.integers(0, 28))
    lx = draw(st.one_of(st.just(0), st.integers(0, 2**29 - 2**19)))
    rx = draw(st.one_of(st.just(2**19), st.just(2**29 - lx), st.integers(2**19, 2**29 - lx)))
    kb = rx.bit_length() - 20
    h = near(0, 8, -2, 30)
    spread = near(0, 2**21, 0, 2**28)
    p0 = draw(st.one_of(st.just(-(2**29)), st.just(2**29 - 1 - spread), st.integers(-(2**29), 2**29 - 1 - spread)))
    ends = [0, spread] + [draw(st.one_of(st.just(0), st.just(spread), st.integers(0, spread))) for _ in range(2)]
    handles = [p0 + v for v in draw(st.permutations(ends))]  # the spread is the one drawn
    ratios = []
    for _ in range(6):
        ratios += [near(2**18, 2**19, 0, 2**22), near(-64, 64, -200, 200)]
    k = [s, lx, rx, kb, h] + handles + ratios
    top = 1 << (29 - s)
    turns = [lx >> s, (lx + rx) >> s, (lx + rx // 2) >> s]
    codes = {0, 1, top - 1, top, top + 1} | {c + d for c in turns for d in (-2, -1, 0, 1, 2) if c + d >= 0}
    codes |= set(draw(st.lists(st.integers(0, top), min_size=20, max_size=20)))
    return k, sorted(codes), past


@settings(max_examples=300, deadline=None)
@given(layouts_near_the_limits())
def test_the_board_accepts_exactly_the_layouts_that_stay_within_31_bits(layout):
    """The board proves a bcm3 safe from its words alone (bcm_fixed.invalid, the layout limits):
    words past any limit are refused, and on any words it accepts every intermediate of the real
    evaluator, at the inputs where it turns, stays within 2**30."""
    k, codes, past = layout
    if past is not None:
        assert invalid(k) is not None, ("accepted past a limit", past, k)
        return
    assert invalid(k) is None, (invalid(k), k)
    assert track(bcm3, codes, k) <= 2**30, k
