"""What forces the spring can hold: the force step's levels through hard contact are found, and the
trim and the experiments stay below them (host/guided/force_calibration.py usable_range)."""

import numpy as np
import pytest

from host.guided.force_identification import usable_range


def _levels(k1, k2, preload, cavity, forces, slack_first=False):
    """The force step's loading levels on the 60 mm side (negative forces) of a simulated spring
    pair (boards/sim/actuator.py spring_force), two rounds: d, f, loading, duty. A level past the
    cavity's wall holds the nut at it, the rest of the force in the contact."""
    import json

    from boards.sim.actuator import Actuator  # the simulated spring pair's law, not a copy of it
    from testkit.interpreters import REPO

    params = json.loads((REPO / "boards" / "sim.json").read_text())["actuator"]
    params["springs"].update(k1_n_per_mm=k1, k2_n_per_mm2=k2, preload_n=preload, cavity_mm=cavity)
    spring = Actuator(dict(params, adc_bits=12), 1).spring_force
    grid = np.linspace(0, cavity, 2001)
    fs = np.array([spring(x) for x in grid])
    d = [float(np.interp(f, fs, grid)) if f <= fs[-1] else cavity for f in forces]
    if slack_first:
        d[0] *= 1.45  # the first level's fibre and friction band
    d, f = np.array(d * 2), np.array(list(forces) * 2)
    duty = np.array([625 * (i % len(forces) + 1) for i in range(len(d))])
    return -d, -f, np.ones(len(d), bool), -duty


def test_a_level_through_the_cavity_wall_limits_the_range():
    # seed 2026112602 of docs/robustness.md: release at 12.3 N, the wall at 18.3 N, levels to 19.1 N
    d, f, loading, duty = _levels(10.9, 0.37, 5.7, 2.0, [2.7, 5.7, 8.8, 11.8, 14.9, 19.1])
    reached, usable, contact = usable_range(d, f, loading, duty, "high")
    assert reached == pytest.approx(19.1) and usable == pytest.approx(14.9) and contact == pytest.approx(19.1)


@pytest.mark.parametrize("spring", [(12.37, 0.65, 10.0), (17.6, 0.32, 12.2), (7.0, 1.5, 5.0)])
def test_a_spring_that_only_softens_at_release_or_hardens_keeps_its_whole_range(spring):
    k1, k2, preload = spring
    forces = [2.1, 4.2, 6.5, 8.8, 11.1, 13.3, 15.6, 17.0]
    d, f, loading, duty = _levels(k1, k2, preload, 2.6, forces, slack_first=True)
    reached, usable, contact = usable_range(d, f, loading, duty, "high")
    assert contact is None and usable == reached == pytest.approx(17.0)


def test_a_gauge_that_does_not_follow_the_spring_stops_the_force_step():
    """--gauge adc on a board with no gauge hooked read 23.6 N, then a flat 33.5 N, and F0 was
    fitted to it without a word. A spring's force moves with its deformation, friction or not."""
    import numpy as np
    import pytest

    from host.errors import UserError
    from host.guided.force_identification import check_gauge_follows

    d = np.array([-0.1, -0.3, -0.5, -0.7, -0.9, -0.7, -0.5, -0.3])
    spring = 12.4 * d + np.array([0.3, 0.3, 0.3, 0.3, 0.3, -0.3, -0.3, -0.3])  # with 0.3 N of friction
    check_gauge_follows(d, spring, "high")  # a real gauge: goes on
    for readings in (np.full(8, 33.5), np.array([23.6] + [33.5] * 7), np.random.default_rng(1).normal(0, 3, 8)):
        with pytest.raises(UserError, match="do not follow the spring"):
            check_gauge_follows(d, readings, "high")


def test_a_segment_inside_the_friction_band_is_neither_judged_nor_compared_against():
    """Seed 202611270601 (1.19 N of block friction, identified 1.10): the 2.2 -> 3.1 N segment
    deformed 60 % more per newton than the rest, the next, ordinary, one read as contact at 3.1 N,
    and the run had no forces left to judge. With the friction band known it is not."""
    forces = [0.37, 2.25, 3.12, 4.54, 5.96, 7.37, 8.79, 10.2, 11.6]
    d, f, loading, duty = _levels(17.5, 1.17, 14.8, 2.0, forces)
    late = np.array([i % len(forces) >= 2 for i in range(len(d))])
    d = np.where(late, d - 0.04, d)  # the band's extra take-up, all of it in the second segment
    assert usable_range(d, f, loading, duty, "high")[2] == pytest.approx(4.54)  # without the band: contact
    reached, usable, contact = usable_range(d, f, loading, duty, "high", friction_n=1.10)
    assert contact is None and usable == reached == pytest.approx(11.6)
