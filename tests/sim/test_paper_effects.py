"""The simulated actuator reproduces the paper's Df effect (the paper's section 5): in force control at
no load, +5 N from D2 = 30 mm, an uncorrected assembly error Df stops the block part-way
("blocking", 43.1 mm in the paper); with D1 corrected by Df the block runs on to the end stop.
Run identically on CPython and MicroPython."""

import pytest
from tests.sim.scenarios import run_both

SCENARIO = """
def run(correct):
    a = Actuator(PARAMS, 1)
    a.place(30.0)
    p1, p2 = a.pots
    lo, hi = 0.0, 2.0  # target deformation for +5 N on the spring curve (bisection)
    for _ in range(50):
        m = (lo + hi) / 2
        if a.spring_force(m) < 5.0:
            lo = m
        else:
            hi = m
    d_target = lo
    s = 0.0
    for i in range(3000):
        # Both pots read through a perfect inherent calibration: D = the wiper's travel.
        d1 = p1.wiper_mm(a.nut_mm)
        d2 = p2.wiper_mm(a.block_mm)
        if correct:
            d1 -= p1.mount_error_mm(d1) - p2.mount_error_mm(d1)  # D1* = D1 - Df(D1), eq. 5
        e = d_target - (d1 - d2)
        s += e * 0.001
        u = 90.0 * e + 10.0 * s  # the paper's PI gains, V per mm
        a.set_motor_voltage(max(-6.0, min(6.0, u)))
        a.advance(0.001)
    return [a.block_mm, a.block_speed_mm_s, a.spring_force_n]
emit({'raw': run(False), 'corrected': run(True), 'fc': a_fc()})
"""


def test_uncorrected_df_blocks_a_5n_no_load_run_and_correction_frees_it():
    r = run_both("def a_fc():\n    return PARAMS['block']['coulomb_n']\n" + SCENARIO)
    block, speed, force = r["raw"]
    assert 35.0 < block < 50.0  # stuck part-way (the paper: 43.1 mm)
    assert speed == 0.0
    assert abs(force) <= r["fc"] * 1.05  # the true spring force cannot beat the slider friction
    block, speed, force = r["corrected"]
    assert block == pytest.approx(60.0)
