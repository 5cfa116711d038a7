"""Bit-exactness of the whole measurement chain: the firmware's Measurement under the real
MicroPython equals the host's integer reference computed in CPython from the same calibration
file (firmware/calibration.py: load_calibration, convert; poly_fixed.poly), for every ADC code of
each pot (the other held fixed), with pwl-table and bcm3 pots; and Df, F0, d(F0) at every integer
input of their declared ranges (plus a margin where the input is clamped)."""


import pytest

from firmware.calibration import convert, load_calibration
from firmware.measurement import STROKE_CLAMP_UM
from firmware.poly_fixed import poly
from firmware.pwl_fixed import DF_PWL_OFFSET, pwl
from host.calibration.file import gain_section, offset_section
from testkit import model
from testkit.interpreters import on_cpython, on_micropython

CASES = "tests.firmware.chain_cases"
BITS = 12
FIXED = [0, 1375, 2048, 4095]  # the other pot: both rails, mid-scale, a code near a knee
MARGIN = 1000


@pytest.fixture(scope="module", params=["pwl", "bcm3"])
def cal_path(request, tmp_path_factory):
    """The model calibration with pwl or bcm3 pots, and no friction (F = F0(d) here)."""
    path = tmp_path_factory.mktemp("chain") / ("%s.json" % request.param)
    # a deformation gain that varies along the stroke (sim.json's pot 2 has no mounting error, so
    # the model's own is 1 everywhere): the step's multiply, rounding and table all take part
    gain = gain_section([-5.0 + 10.0 * i for i in range(8)], [0.93, 0.97, 1.0, 1.02, 1.05, 1.04, 1.1, 1.12])
    offset = offset_section([-5.0 + 5.0 * i for i in range(15)], [0.02 * (-1) ** i - 0.01 * i / 7 for i in range(15)])
    model.write_model_calibration(path, pots=request.param, friction=None, deformation_gain=gain, deformation_offset=offset)
    assert load_calibration(str(path)).pot1[0] == request.param
    return str(path)


def clamp(x):
    return max(-STROKE_CLAMP_UM, min(STROKE_CLAMP_UM, x))


def reference_chain(cal, r1, r2):
    """The chain written out from the calibration's integer evaluators (the paper: D1* = D1 -
    Df_hat(D1), d = (D1* - D2 - z(D2)) g(D2), F = F0(d); positions clamped to +-STROKE_CLAMP_UM)."""
    d1 = clamp(convert(cal.pot1[0], r1, list(cal.pot1[1])))
    d1s = clamp(d1 - poly(d1, list(cal.df)))
    d2 = clamp(convert(cal.pot2[0], r2, list(cal.pot2[1])))
    d = d1s - d2
    if cal.offset is not None:  # less the deformation offset where the block is
        d -= pwl((d2 >> 1) + DF_PWL_OFFSET, list(cal.offset))
    if cal.gain is not None:  # times the deformation gain there, rounded to nearest
        d = (max(-32767, min(32767, d)) * pwl((d2 >> 1) + DF_PWL_OFFSET, list(cal.gain)) + 8192) >> 14
    return [d1, d1s, d2, d, poly(d, list(cal.force))]


@pytest.mark.parametrize("tabulate", [True, False], ids=["tables", "curves"])
def test_every_adc_code_through_the_chain_matches_the_host_reference(cal_path, tabulate):
    """Both ways the step gets D1* and D2: the per-code tables made at boot, and the curves
    evaluated each step (boards with ADCs wider than 12 bits)."""
    cal = load_calibration(cal_path)
    got = on_micropython(CASES, "case_chain(%r, %d, %r, %r)" % (cal_path, BITS, FIXED, tabulate), timeout=300)
    expected = []
    for f in FIXED:
        expected.append([reference_chain(cal, c, f) for c in range(1 << BITS)])
        expected.append([reference_chain(cal, f, c) for c in range(1 << BITS)])
    assert len(got) == len(expected) == 2 * len(FIXED)
    for sweep, (g, e) in enumerate(zip(got, expected)):
        bad = [(c, g[c], e[c]) for c in range(1 << BITS) if g[c] != e[c]]
        assert not bad, "sweep %d (fixed %d): %d codes differ, first %r" % (sweep, FIXED[sweep // 2], len(bad), bad[:3])
    # the sweeps cover the stroke: D1 and D2 span tens of mm, and the force varies
    d1 = [row[0] for row in got[4]]
    d2 = [row[2] for row in got[5]]
    assert max(d1) - min(d1) > 50000 and max(d2) - min(d2) > 50000
    assert len({row[4] for row in got[4]}) > 100
    # the gain took part: d is not D1* - D2 wherever the block is away from a gain of 1
    assert sum(row[3] != row[1] - row[2] for sweep in got for row in sweep) > 1000
    # the in-process firmware (CPython) agrees too
    assert on_cpython(CASES, "case_chain(%r, %d, %r, %r)" % (cal_path, BITS, FIXED[2:3], tabulate)) == got[4:6]


def test_df_and_force_polynomials_at_every_integer_input(cal_path):
    cal = load_calibration(cal_path)
    got = on_micropython(CASES, "case_polys(%r, %d)" % (cal_path, MARGIN), timeout=300)
    for name in ("df", "force", "force_inverse"):
        k = list(getattr(cal, name))
        lo, hi, vals = got[name]
        assert (lo, hi) == (k[2] - MARGIN, k[3] + MARGIN)
        assert len(vals) == hi - lo + 1 > 2 * MARGIN + 1000, (name, lo, hi)  # a real range, every integer
        expected = [poly(x, k) for x in range(lo, hi + 1)]
        bad = [x for x, g, e in zip(range(lo, hi + 1), vals, expected) if g != e]
        assert not bad, "%s differs at %d inputs, first %r" % (name, len(bad), bad[:5])
        assert vals[:MARGIN] == [vals[MARGIN]] * MARGIN  # clamped below the range
        assert vals[-MARGIN:] == [vals[-MARGIN - 1]] * MARGIN  # and above
