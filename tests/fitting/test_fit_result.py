"""FitResult: evaluation, inversion of monotone fits (every model), refusal for the others."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from host.fitting.models import MODELS, fit_model

ORDERS = {"bcm": 3, "pcm": 5, "pcm-raw": 5, "cheb": 5, "spline": 6, "pchip": 6, "lut": 8, "pwl": 5}


@st.composite
def monotone_sweeps(draw):
    """A pot sweep on ADC codes: two knees, either direction, a little noise."""
    rng = np.random.default_rng(draw(st.integers(0, 2**16)))
    x = np.sort(rng.choice(4096, 400, replace=False)).astype(float)
    u = x / 4095
    k1, k2 = draw(st.floats(0.05, 0.3)), draw(st.floats(0.7, 0.95))
    y = u + draw(st.floats(0.5, 3)) * (np.maximum(u - k2, 0) - np.maximum(k1 - u, 0))
    y = 60 * (y - y.min()) / np.ptp(y) * draw(st.sampled_from([1, -1])) + rng.normal(0, 0.02, x.size)
    return x, y


@settings(max_examples=12, deadline=None)
@given(monotone_sweeps(), st.integers(0, 2**16))
def test_inverse_undoes_every_monotone_fit(sweep, seed):
    x, y = sweep
    probe = np.random.default_rng(seed).uniform(x[0], x[-1], 50)
    for name in MODELS:
        r = fit_model(name, x, y, ORDERS[name])
        if not r.monotone:
            with pytest.raises(ValueError, match="monotone"):
                r.inverse(r(probe))
            continue
        back = r.inverse(r(probe))
        span = x[-1] - x[0]
        assert np.all(np.abs(r(back) - r(probe)) <= 1e-6 * np.ptp(y)), name  # 60 nm on 60 mm
        # x itself, to the bisection's 1e-9 of the range, wherever the curve is not flat (a
        # table may be flat in places, and then any x of the flat part is an answer)
        slope = np.abs(r(probe + 0.5) - r(probe - 0.5))
        steep = slope > 1e-6
        assert np.all(np.abs(back - probe)[steep] <= 1e-8 * span), name
        assert isinstance(r.inverse(float(r(probe[0]))), float)


def test_inverse_clamps_beyond_the_range_and_refuses_a_turning_curve():
    x = np.linspace(0, 4095, 300)
    r = fit_model("bcm", x, 60 - 60 * x / 4095, 3)  # a decreasing pot
    assert r.monotone
    assert r.inverse([1e6, -1e6]) == pytest.approx([0, 4095], abs=1e-5)  # to the bisection tolerance
    bump = fit_model("pcm", x, np.sin(x / 4095 * 3 * np.pi), 6)
    assert not bump.monotone
    with pytest.raises(ValueError, match="monotone"):
        bump.inverse(0.5)


def _dip(x, at=30001.0):
    """Rising, but turning back for about 2 codes at `at`: between any two points of a 4,097-point
    grid over 16 bits (16 codes apart), so only a check of every code sees it."""
    return x - 3.0 * np.exp(-(((x - at) / 1.5) ** 2))


def fit_dip(x, y, order):
    from host.fitting.fit_result import FitResult

    return FitResult("dip", order, 1, {}, (float(np.min(x)), float(np.max(x))), curve=_dip)


def test_monotone_check_covers_every_code_of_a_16_bit_adc(monkeypatch):
    from host.fitting import models
    from host.fitting.fit_result import FitResult, is_monotone

    codes = np.arange(0, 65536, 3.0)
    r = FitResult("dip", 1, 1, {}, (0.0, 65535.0), curve=_dip)
    assert is_monotone(r)  # the grid misses it
    assert not is_monotone(r, codes)  # every code does not
    assert is_monotone(r, codes + 0.5)  # not codes: the grid again
    monkeypatch.setitem(models.MODELS, "dip", ("tests.fitting.test_fit_result", "fit_dip", "a curve with a 2-code dip"))
    assert not fit_model("dip", codes, codes, 1).monotone  # what fit_model reports for code data
