"""Physics sanity of the simulated actuator; every case runs identically on both interpreters."""

import json
import math

import pytest
from tests.sim.scenarios import REPO, run_both

PARAMS = json.loads((REPO / "boards" / "sim.json").read_text())["actuator"]


def drive_force_n(volts):
    """Stall force at the nut from the motor constants (no speed, so no back-EMF)."""
    m, s = PARAMS["motor"], PARAMS["screw"]
    G = m["gear_ratio"] * 2 * math.pi / (s["lead_mm"] / 1000)
    return s["efficiency"] * m["kt_nm_per_a"] * G * volts / m["resistance_ohm"]


def spring_n(d):
    """The documented curve: the paper's k1 d + k2 d|d| until one spring loses its preload, then
    half the slope (only the other spring still pushes)."""
    sp = PARAMS["springs"]
    k1, k2 = sp["k1_n_per_mm"], sp["k2_n_per_mm2"]
    rel = sp["preload_n"] / (k1 / 2)
    if abs(d) <= rel:
        return k1 * d + k2 * d * abs(d)
    f_rel = k1 * rel + k2 * rel * rel
    return math.copysign(f_rel + (k1 + 2 * k2 * rel) / 2 * (abs(d) - rel), d)


def test_spring_curve_matches_spec_then_softens_past_the_preload():
    r = run_both("""
a = Actuator(PARAMS, 1)
ds = [i * 0.01 - 2.0 for i in range(401)]
emit({'f': [a.spring_force(d) for d in ds], 'rel': a.d_release})
""")
    sp = PARAMS["springs"]
    rel = r["rel"]
    assert 1.0 < rel < sp["cavity_mm"]  # the preload holds over the paper's 0-15 N range
    ds = [i * 0.01 - 2.0 for i in range(401)]
    for d, f in zip(ds, r["f"]):
        assert f == pytest.approx(spring_n(d), rel=1e-12, abs=1e-12)
        if abs(d) <= rel:
            assert f == pytest.approx(12.37 * d + 0.65 * d * abs(d), rel=1e-12, abs=1e-12)
    slope = [(b - a) / 0.01 for a, b in zip(r["f"], r["f"][1:])]
    assert slope[200] == pytest.approx(12.37, rel=0.01)  # about 12.4 N/mm near zero
    assert max(slope) < 12.37 + 2 * 0.65 * rel + 0.1
    assert slope[0] < 0.6 * max(slope)  # past the release only one spring acts
    assert all(s > 0 for s in slope)


def test_passive_system_loses_energy_and_settles():
    r = run_both("""
a = Actuator(PARAMS, 7)
a.place(30.0, 1.5)
M1 = a.M1
def energy():
    d = a.deformation_mm
    ke = 0.5 * M1 * (a.nut_speed_mm_s / 1000) ** 2 + 0.5 * a.m2 * (a.block_speed_mm_s / 1000) ** 2
    pe = (a.k1 * d * d / 2 + a.k2 * abs(d) ** 3 / 3) / 1000
    return ke + pe
e = [energy()]
for i in range(1500):
    a.advance(0.001)
    if i % 10 == 9:
        e.append(energy())
emit({'e': e, 'v1': a.nut_speed_mm_s, 'v2': a.block_speed_mm_s, 'd': a.deformation_mm,
      'f': a.spring_force_n})
""")
    e = r["e"]
    assert e[0] > 0.01  # 1.5 mm of spring holds ~15 mJ
    for before, after in zip(e, e[1:]):
        assert after <= before * (1 + 1e-9) + 1e-12
    assert e[-1] < 1e-3 * e[0]
    assert abs(r["v1"]) < 1e-3 and abs(r["v2"]) < 1e-3
    # At rest the spring cannot exceed what Coulomb friction of the block holds.
    assert abs(r["f"]) <= PARAMS["block"]["coulomb_n"] * 1.05


@pytest.mark.parametrize("volts", [3.0, -2.0])
def test_constant_voltage_gives_the_speed_the_motor_constants_predict(volts):
    r = run_both("""
a = Actuator(PARAMS, 1)
a.place(30.0 - 20.0 * %r / abs(%r))
a.set_motor_voltage(%r)
for i in range(400):
    a.advance(0.001)
x0 = a.nut_mm
for i in range(100):
    a.advance(0.001)
emit({'v': (a.nut_mm - x0) / 0.1, 'G': a.G, 'i': a.motor_current_a})
""" % (volts, volts, volts))
    m, s, b = PARAMS["motor"], PARAMS["screw"], PARAMS["block"]
    G = r["G"]
    ideal = volts / (m["ke_v_s_per_rad"] * G) * 1000  # mm/s with no load at all
    # With the block's friction as the only load: drive - back-EMF term = Coulomb + viscous.
    b_motor = s["efficiency"] * m["kt_nm_per_a"] * m["ke_v_s_per_rad"] * G * G / m["resistance_ohm"]
    f_c = math.copysign(b["coulomb_n"], volts)
    loaded = (drive_force_n(volts) - f_c) / (b_motor + b["viscous_n_s_per_m"]) * 1000
    assert r["v"] == pytest.approx(loaded, rel=0.01)
    assert r["v"] == pytest.approx(ideal, rel=0.05)
    assert abs(r["v"]) < abs(ideal)
    assert r["i"] * volts > 0  # the motor is driving, not braking


def test_stalled_at_end_stop_the_spring_balances_the_drive_on_its_curve():
    r = run_both("""
a = Actuator(PARAMS, 2)
a.place(55.0)
a.set_motor_voltage(2.0)
for i in range(1500):
    a.advance(0.001)
emit({'d': a.deformation_mm, 'f': a.spring_force_n, 'x2': a.block_mm, 'v1': a.nut_speed_mm_s})
""")
    assert r["x2"] == 60.0
    assert abs(r["v1"]) < 1e-3
    assert r["f"] == pytest.approx(spring_n(r["d"]), rel=1e-12)
    assert r["f"] == pytest.approx(drive_force_n(2.0), rel=0.01)
    # About 12.4 N/mm near zero: the deformation is close to force / 12.37 but a bit less.
    assert 0.9 * r["f"] / 12.37 < r["d"] < r["f"] / 12.37


def test_end_stops_and_cavity_hold_at_full_voltage():
    r = run_both("""
a = Actuator(PARAMS, 3)
a.place(20.0)
a.set_motor_voltage(-6.0)
lo_block = 99.0
lo_d = 99.0
for i in range(1500):
    a.advance(0.001)
    lo_block = min(lo_block, a.block_mm)
    lo_d = min(lo_d, a.deformation_mm)
low = (a.block_mm, a.deformation_mm, lo_block, lo_d)
a.set_motor_voltage(6.0)
hi_block = -99.0
for i in range(2500):
    a.advance(0.001)
    hi_block = max(hi_block, a.block_mm)
emit({'low': low, 'high': (a.block_mm, a.deformation_mm, hi_block), 'cav': a.cavity})
""")
    cav = r["cav"]
    block, d, lo_block, lo_d = r["low"]
    assert block == 0.0 and lo_block == 0.0
    # 6 V stall force (~36 N) exceeds the spring at full deformation (~27 N): hard contact.
    assert drive_force_n(6.0) > spring_n(cav)
    assert d == pytest.approx(-cav, abs=1e-9) and lo_d >= -cav - 1e-9
    block, d, hi_block = r["high"]
    assert block == 60.0 and hi_block == 60.0
    assert d == pytest.approx(cav, abs=1e-9)


def test_force_gauge_through_fibre_balances_the_spring():
    r = run_both("""
a = Actuator(PARAMS, 4)
a.place(50.0)
a.set_load('gauge', anchor_mm=45.0, stiffness_n_per_mm=20.0)
a.set_motor_voltage(-1.5)
slack = []
for i in range(3000):
    a.advance(0.001)
    if a.block_mm > 45.0:
        slack.append(a.external_force_n)
emit({'x2': a.block_mm, 'fs': a.spring_force_n, 'fe': a.external_force_n,
      'tension': a.gauge_tension_n, 'slack': slack, 'v1': a.nut_speed_mm_s})
""")
    assert all(f == 0.0 for f in r["slack"]) and len(r["slack"]) > 10
    assert r["x2"] < 45.0
    assert r["fe"] == pytest.approx(20.0 * (45.0 - r["x2"]), rel=1e-9)
    assert r["tension"] == r["fe"]
    # Static: motor stall force = spring force = fibre tension, within the block's friction.
    assert abs(r["v1"]) < 1e-2
    assert r["fs"] == pytest.approx(-drive_force_n(1.5), rel=0.01)
    assert abs(r["fs"] + r["fe"]) <= PARAMS["block"]["coulomb_n"] * 1.05


def test_one_ms_ticks_with_few_substeps_track_a_finely_resolved_run():
    """The default sub-step count is converged: 15x finer steps move the answer by < 20-ish um."""
    r = run_both("""
def world(max_omega_dt, gauge):
    p = json.loads(json.dumps(PARAMS))
    p['integration']['max_omega_dt'] = max_omega_dt
    a = Actuator(p, 1)
    a.place(50.0)
    if gauge:
        a.set_load('gauge')
    return a
res = {}
for gauge in (False, True):
    coarse = world(PARAMS['integration']['max_omega_dt'], gauge)
    fine = world(0.02, gauge)
    dx = df = 0.0
    for i in range(1500):
        for a in (coarse, fine):
            a.set_motor_voltage(-4.0 if i < 1000 else 3.0)  # hit the stop/fibre, then reverse
            a.advance(0.001)
        dx = max(dx, abs(coarse.block_mm - fine.block_mm))
        df = max(df, abs(coarse.spring_force_n - fine.spring_force_n))
    res[str(gauge)] = [coarse._n_sub, fine._n_sub, dx, df]
emit(res)
""")
    for n_coarse, n_fine, dx, df in r.values():
        assert n_fine >= 10 * n_coarse
        assert dx < 0.05  # mm
        assert df < 0.5  # N, at the stick/slip and contact instants
