"""BCM-3 in integer arithmetic: accuracy against float64 at every ADC code, the 31-bit bound, the
exporter's refusals, and bit-identical results under the real MicroPython."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware.bcm_fixed import bcm3
from host.fixed_export import TrackedInt, export_bcm3, export_pot, track
from host.models import fit_model
from host.sweep import load_sweep
from test_fixed_on_micropython import evaluate_on_micropython

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


def curves():
    """Curves a fit could return: lx/ux near the rails, weight ratios within [1/60, 60],
    handles in the fitter's widened reference range [-6, 66] mm (sorted or not)."""
    return st.builds(
        lambda lx, ux, logw, p, sort: {
            "lx": lx,
            "rx": ux - lx,
            "weights": [60.0**v for v in logw],
            "handles": sorted(p) if sort else p,
        },
        st.floats(0, 400),
        st.floats(3600, 4095),
        st.lists(st.floats(0, 1), min_size=4, max_size=4),
        st.lists(st.floats(-6, 66), min_size=4, max_size=4),
        st.booleans(),
    )


@settings(max_examples=10, deadline=None)
@given(curves())
def test_random_curves_error_model_and_31_bits(c):
    """Error <= 3 um + 0.02 code x the steepest local slope (what Q17 t can resolve), every
    intermediate within 2**30, and the exporter refuses exactly the curves over 0.5 LSB."""
    try:
        k = export_bcm3(c, 12)
        refused = False
    except ValueError as e:
        assert "bound" in str(e)
        k = export_bcm3(c, 12, max_error_um=1e9)
        refused = True
    reference = rational_bernstein_um(c, CODES)
    err = np.max(np.abs(integer_curve(k) - reference))
    fine = rational_bernstein_um(c, np.linspace(0, 4095, 4095 * 16 + 1))
    steepest = np.max(np.abs(np.diff(fine))) * 16
    assert err <= 3.0 + 0.02 * steepest
    assert k.max_intermediate <= 2**30
    assert refused == (err > 0.5 * (reference.max() - reference.min()) / 4096)


def test_cpython_and_micropython_agree_on_many_curves():
    rng = np.random.default_rng(7)
    cases = [export_bcm3(KNEE, 12)]
    while len(cases) < 8:
        lx, ux = rng.uniform(0, 400), rng.uniform(3600, 4095)
        c = {"lx": lx, "rx": ux - lx, "weights": list(60.0 ** rng.uniform(0, 1, 4)), "handles": list(rng.uniform(-6, 66, 4))}
        cases.append(export_bcm3(c, 12, max_error_um=1e9))
    inputs = list(range(-20, 4116))
    expected = [[bcm3(x, list(k)) for x in inputs] for k in cases]
    assert evaluate_on_micropython("bcm_fixed", "bcm3", cases, inputs) == expected


def test_refuses_what_it_cannot_represent():
    with pytest.raises(ValueError, match="degree 3"):
        export_bcm3({"lx": 0, "rx": 4095, "weights": [1] * 6, "handles": [0, 10, 20, 30, 40, 60]}, 12)
    with pytest.raises(ValueError, match="weight ratio"):
        export_bcm3({"lx": 0, "rx": 4095, "weights": [1, 1e7, 1, 1], "handles": [0, 20, 40, 60]}, 12)
    with pytest.raises(ValueError, match="positive"):
        export_bcm3({"lx": 0, "rx": 4095, "weights": [1, -2, 1, 1], "handles": [0, 20, 40, 60]}, 12)
    with pytest.raises(ValueError, match="ADC range"):
        export_bcm3({"lx": 0, "rx": 40950, "weights": [1, 2, 2, 1], "handles": [0, 20, 40, 60]}, 12)
    with pytest.raises(ValueError, match="spread"):
        export_bcm3({"lx": 0, "rx": 4095, "weights": [1, 2, 2, 1], "handles": [0, 2000, 4000, 6000]}, 12)
    # a curve that swings 60 mm up, down and up again, 20x steeper than its mean slope in
    # places: a Q17 t cannot resolve 0.5 LSB there (measured: 30 um off)
    with pytest.raises(ValueError, match="bound"):
        export_bcm3({"lx": 0.3, "rx": 4000.3, "weights": [1, 60, 60, 1], "handles": [0, 60, 0, 60]}, 12)


def test_instrumentation_sees_an_overflow():
    """The tracked run is not a formality: constants outside the layout's limits are caught."""
    k = list(export_bcm3(KNEE, 12))
    k[11] = k[8] + 2**23  # a handle spread 8x the limit
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
