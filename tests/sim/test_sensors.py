"""Simulated sensors: pot knee curves, assembly error Df, ADC noise, read_u16 scaling, rails,
wiper-lift faults and seeds; every case run identically on CPython and MicroPython."""

import json
import statistics

import pytest
from tests.sim.scenarios import REPO, run_both

BOARD = json.loads((REPO / "boards" / "sim.json").read_text())
POTS = BOARD["actuator"]["pots"]


def test_each_pot_curve_has_two_knees_with_the_configured_slopes():
    r = run_both("""
out = {}
for name in ('pot1', 'pot2'):
    a = Actuator(PARAMS, 1)
    p = a.pots[0 if name == 'pot1' else 1]
    us = [i / 2000 for i in range(2001)]
    out[name] = [p.curve(u) for u in us]
emit(out)
""")
    for name in ("pot1", "pot2"):
        cfg = POTS[name]
        (u0, g0), (u1, g1), (u2, g2), (u3, g3) = cfg["curve"]
        h = cfg["knee_halfwidth"]
        slopes = [(g1 - g0) / (u1 - u0), (g2 - g1) / (u2 - u1), (g3 - g2) / (u3 - u2)]
        assert slopes[1] > 2 * slopes[0] and slopes[1] > 2 * slopes[2]  # real knees
        g = r[name]
        du = 1 / 2000
        d = [(b - a) / du for a, b in zip(g, g[1:])]
        assert min(d) > 0  # strictly increasing: invertible
        for i, s in enumerate(d):
            u = (i + 0.5) * du
            if u < u1 - h:
                assert s == pytest.approx(slopes[0], rel=1e-6)
            elif u1 + h < u < u2 - h:
                assert s == pytest.approx(slopes[1], rel=1e-6)
            elif u > u2 + h:
                assert s == pytest.approx(slopes[2], rel=1e-6)
        # Smooth (C1): the slope never jumps between neighbouring samples.
        step = max(abs(b - a) for a, b in zip(d, d[1:]))
        jump = max(abs(slopes[1] - slopes[0]), abs(slopes[2] - slopes[1]))
        assert step < 1.5 * jump * du / (2 * h)  # the parabola spreads each jump over 2h
        assert g[0] == g0 and g[-1] == g3
        assert g[int(u1 * 2000)] == pytest.approx(g1, abs=0.3 * h * abs(slopes[1] - slopes[0]))


def test_assembly_error_is_flat_mid_stroke_and_grows_toward_the_ends():
    r = run_both("""
a = Actuator(PARAMS, 1)
xs = [i * 0.5 for i in range(121)]
df = [a.pots[0].wiper_mm(x) - a.pots[1].wiper_mm(x) for x in xs]
# The same Df seen through the ADC: the reference rides on each pot's wiper in turn.
seen = []
for x in (2.0, 30.0, 58.0):
    a.place(x)
    a.set_reference('pot1')
    c1 = sum(a.adc_code('reference') for i in range(64))
    a.set_reference('pot2')
    c2 = sum(a.adc_code('reference') for i in range(64))
    seen.append((c1 - c2) / 64)
emit({'df': df, 'seen': seen})
""")
    df = r["df"]
    xs = [i * 0.5 for i in range(121)]
    # The documented shape: the paper's eq. 6 with the opposite sign (docs/simulated-actuator.md says why).
    for x, v in zip(xs, df):
        spec = -1.922222e-6 * x**4 + 2.632e-4 * x**3 - 1.63e-2 * x**2 + 0.46 * x - 4.6
        assert v == pytest.approx(-spec, abs=2e-3), x
    mid = [v for x, v in zip(xs, df) if 20 <= x <= 40]
    assert max(abs(v) for v in mid) < 0.4  # the pots agree in 20-40 mm
    assert 2 < df[0] < 6 and 2 < df[-1] < 6  # and drift a few mm apart toward the ends
    left = [v for x, v in zip(xs, df) if x <= 20]
    right = [v for x, v in zip(xs, df) if x >= 40]
    assert all(a > b for a, b in zip(left, left[1:]))
    assert all(a < b for a, b in zip(right, right[1:]))
    # Smooth: bounded second differences (no steps or kinks).
    second = [abs(a - 2 * b + c) for a, b, c in zip(df, df[1:], df[2:])]
    assert max(second) < 0.05
    ref = BOARD["actuator"]["reference"]
    mm_per_code = ref["span_mm"] / 4095
    for x, seen in zip((2.0, 30.0, 58.0), r["seen"]):
        assert seen * mm_per_code == pytest.approx(df[int(x * 2)], abs=3 * mm_per_code)


def test_adc_noise_has_the_configured_standard_deviation_and_no_bias():
    r = run_both("""
a = Actuator(PARAMS, 11)
a.place(33.3)
out = {}
for name in ('pot1', 'pot2', 'reference', 'gauge'):
    out[name] = [a.adc_code(name) for i in range(6000)]
    out[name + '_true'] = a._base_q8[('pot1', 'pot2', 'reference', 'gauge').index(name)] / 256 - 0.5
emit(out)
""")
    cfg = BOARD["actuator"]
    sigmas = {"pot1": POTS["pot1"]["noise_lsb"], "pot2": POTS["pot2"]["noise_lsb"],
              "reference": cfg["reference"]["noise_lsb"], "gauge": cfg["gauge"]["noise_lsb"]}
    for name, sigma in sigmas.items():
        codes = r[name]
        # Rounding to whole codes adds the uniform quantisation variance 1/12 LSB^2.
        expected = (sigma ** 2 + 1 / 12) ** 0.5
        assert statistics.pstdev(codes) == pytest.approx(expected, rel=0.06), name
        assert statistics.fmean(codes) == pytest.approx(r[name + "_true"], abs=0.08), name


def test_read_u16_scaling_rails_and_wiper_lift():
    r = run_both("""
a = Actuator(PARAMS, 5)
a.place(30.0)
mid = [a.adc_u16('pot1') for i in range(50)]
a.inject_fault('pot1', 'wiper_lift')
lifted_high = [a.adc_u16('pot1') for i in range(5)]
other = a.adc_u16('pot2')
a.inject_fault('pot2', 'wiper_lift', rail='low')
lifted_low = [a.adc_u16('pot2') for i in range(5)]
a.clear_faults()
healed = a.adc_u16('pot1')
a.set_reference('nut')
a.place(60.0, 2.0)  # nut at 62 mm, inside the reference's span
ref_end = a.adc_code('reference')
a.set_load('constant', force_n=0.0)
a.gauge['zero_fraction'] = -0.5
a.place(60.0)
gauge_low = [a.adc_code('gauge') for i in range(5)]
emit({'mid': mid, 'high': lifted_high, 'low': lifted_low, 'other': other, 'healed': healed,
      'ref_end': ref_end, 'gauge_low': gauge_low})
""")
    for v in r["mid"]:
        c = v >> 4
        assert v == (c << 4) | (c >> 8)  # MicroPython's 12-bit to 16-bit scaling
        assert 0 < c < 4095
    assert r["high"] == [65535] * 5
    assert r["low"] == [0] * 5
    assert 0 < r["other"] < 65535 and 0 < r["healed"] < 65535
    ref = BOARD["actuator"]["reference"]
    assert r["ref_end"] == pytest.approx((62.0 - ref["zero_mm"]) / ref["span_mm"] * 4095, abs=3)
    assert r["gauge_low"] == [0] * 5  # an input driven beyond the rail saturates at code 0


def test_seed_makes_runs_repeatable_and_different_seeds_differ():
    body = """
out = []
for seed in (1, 1, 2):
    a = Actuator(PARAMS, seed)
    a.set_motor_voltage(2.5)
    codes = []
    for i in range(200):
        a.advance(0.001)
        codes.append(a.adc_u16('pot1'))
    out.append([codes, a.nut_mm])
emit({'runs': out})
"""
    r = run_both(body)
    (c1, x1), (c2, x2), (c3, x3) = r["runs"]
    assert c1 == c2 and x1 == x2
    assert c1 != c3
    assert x1 == x3  # the seed changes sensor noise and gauge drift, not the mechanics


def test_gauge_reads_the_fibre_tension_plus_a_slow_bounded_zero_drift():
    r = run_both("""
out = []
for seed in (1, 2, 3):
    a = Actuator(PARAMS, seed)
    a.set_load('gauge', anchor_mm=45.0, stiffness_n_per_mm=20.0)
    row = []
    for t in (0.0, 60.0, 3600.0):
        a.time_s = t
        a.place(44.5)  # fibre taut: 10 N
        row.append((a.gauge_tension_n, a.gauge_reading_n,
                    sum(a.adc_code('gauge') for i in range(200)) / 200))
    out.append(row)
emit({'rows': out})
""")
    g = BOARD["actuator"]["gauge"]
    drifts = []
    for row in r["rows"]:
        (t0, r0, c0), (t1, r1, c1), (t2, r2, c2) = row
        assert t0 == t1 == t2 == pytest.approx(10.0)
        assert r0 == t0  # no drift at power-up
        assert abs(r1 - t1) <= g["drift_n_per_min"] + 1e-12  # at most the rate after 1 min
        rate = (r1 - t1) / 60.0
        # Linear in time, bounded at drift_max_n.
        assert abs(r2 - t2) == pytest.approx(min(abs(rate) * 3600.0, g["drift_max_n"]), rel=1e-9)
        for reading, code in ((r0, c0), (r1, c1), (r2, c2)):
            want = (g["zero_fraction"] + reading / g["n_per_fraction"]) * 4095
            assert code == pytest.approx(want, abs=0.3)
        drifts.append(r1 - t1)
    assert len(set(drifts)) == 3  # the seed picks the drift rate


def _table_pot_params(curve_table):
    pot = dict(json.loads((REPO / "boards" / "sim.json").read_text())["actuator"]["pots"]["pot1"])
    pot.pop("curve")
    pot.pop("knee_halfwidth")
    pot["curve_table"] = curve_table
    return pot


def test_a_pot_can_take_its_curve_from_a_table():
    """A listed table is interpolated linearly (same floats on both interpreters), a noisy one
    is made non-decreasing (isotonic), and a table that cannot be a pot is refused."""
    from boards.sim.potentiometer import Potentiometer, table_curve

    pot = Potentiometer(_table_pot_params([[0, 0.1], [0.5, 0.4], [1, 0.9]]))
    for u, g in ((0.0, 0.1), (0.25, 0.25), (0.5, 0.4), (0.75, 0.65), (1.0, 0.9), (-1, 0.1), (2, 0.9)):
        assert abs(pot.curve(u) - g) < 1e-12, (u, pot.curve(u), g)
    u, g = table_curve([[0, 0.1], [0.2, 0.3], [0.4, 0.2], [0.6, 0.5], [1, 0.9]])
    assert g == [0.1, 0.25, 0.25, 0.5, 0.9] and u[0] == 0 and u[-1] == 1
    for bad in ([[0, 0.1]], [[0, 0.1], [0, 0.2]], [[0, -0.1], [1, 0.5]], [[0, 0.1], [1, 1.5]]):
        with pytest.raises(ValueError):
            table_curve(bad)
    code = (
        "from boards.sim.potentiometer import Potentiometer\n"
        "p = Potentiometer(%r)\n"
        "emit({'g': [p.fraction(x / 4.0) for x in range(-20, 260)]})\n" % _table_pot_params([[0, 0.1], [0.3, 0.2], [0.8, 0.85], [1, 0.9]])
    )
    got = run_both(code)
    assert len(got["g"]) == 280


def test_a_real_measured_adc_curve_as_the_pot_is_calibrated_to_its_noise_floor(realdata_dir):
    """Pot 1 simulated with the ESP32 ADC transfer curve measured by rupayan555 (knees at both
    ends, 8 % of span from a straight line): a noisy sweep of it, fitted with --model auto as
    `host calibrate` does, gives positions within a tenth of a millimetre of the wiper's, where a
    straight line through the same sweep is off by millimetres."""
    import numpy as np

    from boards.sim.actuator import Actuator
    from host.fitting.model_select import select_model
    from host.fitting.noise_floor import estimate_noise

    params = json.loads((REPO / "boards" / "sim.json").read_text())["actuator"]
    params["pots"]["pot1"] = _table_pot_params(
        {"csv": str(realdata_dir / "esp32_adc_rupayan555.csv"), "x": "reference", "y": "raw", "y_full_scale": 4095})
    world = Actuator(dict(params, adc_bits=12), 5)
    xs = np.linspace(0.0, 60.0, 1201)
    codes, travel = [], []
    for x in xs:
        world.place(x)
        codes.append(world.adc_code("pot1"))
        travel.append(world.pots[0].wiper_mm(x))
    order = np.argsort(codes, kind="stable")
    c = np.asarray(codes, float)[order]
    t = np.asarray(travel)[order]
    keep = (c > 0) & (c < 4095)  # the ADC's clipped ends carry no position
    c, t = c[keep], t[keep]
    line = np.polyval(np.polyfit(c, t, 1), c) - t
    chosen = select_model(c, t, noise=estimate_noise(c, t)).result
    err = chosen(c) - t
    assert np.max(np.abs(line)) > 2.0, np.max(np.abs(line))
    assert np.sqrt(np.mean(err**2)) < 0.1 and chosen.monotone, (chosen.model, np.sqrt(np.mean(err**2)))


def test_the_model_pot_tables_pair_each_knot_with_its_unrounded_code():
    """testkit.model's exact pot tables (`unrounded`, the offline benches' --exact) put a knot every
    1/8 mm. Paired with the rounded noise-free code, each knot was up to half a code (7-10 um) off, and on
    a 13 N/mm spring the deformation of two pots that far off is 0.1-0.25 N of force: what stops 41
    and 42 took for the loop's share was partly this table's. Whole codes between the knots must
    read their position within 2 um mid-stroke."""
    import numpy as np

    from boards.sim.actuator import Actuator
    from firmware.pwl_fixed import pwl
    from testkit import model

    board = model.sim_board()
    sections = model.model_sections(board, n_points=60 * 8 + 1, unrounded=True)
    world = Actuator(dict(board["actuator"], adc_bits=board["adc_bits"]), 1)
    worst = 0.0
    for x in np.linspace(15.0, 45.0, 301):
        world.place(x)
        for i, name in enumerate(("pot1", "pot2")):
            v = world.code_value(name)
            c0 = int(v)
            t0, t1 = (pwl(c, sections[name]["fixed"]) for c in (c0, c0 + 1))
            travel_um = 1000.0 * (x + world.pots[i].mount_error_mm(x))
            worst = max(worst, abs(t0 + (v - c0) * (t1 - t0) - travel_um))
    assert worst < 2.0, worst
