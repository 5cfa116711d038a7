"""The firmware against the simulated actuator, and booting from real calibration files."""

import json

import numpy as np
import pytest

from testkit import interpreters, model

CASES = "tests.sim.firmware_cases"
FORCE_CASES = "tests.sim.force_cases"
TARGETS = [10000, 45000, 30000, 5000, 55000]


@pytest.fixture(scope="module")
def cal_path(tmp_path_factory):
    """The simulated actuator's model calibration file (testkit.model)."""
    path = tmp_path_factory.mktemp("sim") / "cal.json"
    model.write_model_calibration(path)
    return str(path)


def _cases(call):
    """The case module a call's case lives in: the force cases apart from the others."""
    return FORCE_CASES if call.startswith("case_force") else CASES


def on_cpython(call):
    return interpreters.on_cpython(_cases(call), call)


def on_micropython(call):
    return interpreters.on_micropython(_cases(call), call)


def test_position_mode_reaches_targets_on_sim(cal_path):
    call = "case_position_sim(%r, %r)" % (cal_path, TARGETS)
    for out in (on_cpython(call), on_micropython(call)):
        # Over 0.3 s after 1.5 s of settling, for targets across 5-55 mm (the paper's usable
        # range). One code is ~16 um of travel on the simulated pots; a reading is the mean of 4
        # reads with 1.5 LSB noise each (sigma ~12 um), so the firmware's own D2 strays up to
        # ~4 sigma plus the table's error near the knees: 150 um. The true wiper travel (the
        # calibration reference) has the noise averaged out by the loop: 100 um (~6 codes),
        # 40x better than the paper's 4.2 mm. Overshoot: the slew limit (500/step) and the
        # motor's inertia allow a few hundred um; 1 mm is the bound.
        assert out["fw_err_um"] <= 150, out
        assert out["true_err_um"] <= 100, out
        assert out["overshoot_um"] <= 1000, out


def test_boot_reads_calibration_file_and_refuses_a_corrupt_one(tmp_path, cal_path):
    good = tmp_path / "good.json"
    good.write_text(open(cal_path).read())
    text = good.read_text()
    i = text.index("fixed") + 12
    while not text[i].isdigit():
        i += 1
    bad = tmp_path / "bad.json"
    bad.write_text(text[:i] + ("9" if text[i] != "9" else "8") + text[i + 1 :])  # one digit flipped
    call = "case_boot_calibration_file(%r, %r)" % (str(good), str(bad))
    assert on_cpython(call) == on_micropython(call)


def test_force_mode_holds_gauge_targets_on_sim(cal_path):
    call = "case_force_sim(%r, %r)" % (cal_path, [-5000, -10000, -15000])
    for out in (on_cpython(call), on_micropython(call)):
        # The paper's steps (the paper's section 5): -5, -10, -15 N, measured -5.2 / -10.7 / -14.4 N. After 2 s,
        # the mean of the firmware's own estimate over 0.5 s: the PI removes its error to within
        # the estimate's noise (two pots, ~17 um of deformation each read, x 12.4 mN/um, about
        # 200 mN sigma per step, averaged over 500 steps) plus slow integral convergence: 200 mN.
        # The true spring force also carries the calibration's deformation error (tens of um
        # between the two pots' tables and the Df fit, x 12.4 mN/um): 1 N, the paper's worst.
        assert out["est_err_mN"] <= 200, out
        assert out["true_err_mN"] <= 1000, out


def test_force_points_stop_loading_at_the_force_range(cal_path):
    """The replayed force step (bench/bench_force_steps_offline.py --refit) ends its loading at
    the first level whose load reaches the range, as the guided step's --force-range does, and
    unloads from there level by level."""
    levels = [800 * i for i in range(1, 12)]
    rows = on_cpython("case_force_points_sim(%r, 'high', %r, stop_mN=8000)" % (cal_path, levels))
    loads = [abs(load) for _, load, loading in rows if loading]
    assert loads[-1] >= 8000 and max(loads[:-1]) < 8000 and len(loads) < len(levels), loads
    unloads = [abs(load) for _, load, loading in rows if not loading]
    assert len(unloads) == len(loads) - 1 and unloads == sorted(unloads, reverse=True), unloads


def test_friction_compensated_force_steps_within_2_percent_on_both_sides(tmp_path, cal_path):
    """The force identification of the guided step (open-loop duty steps against a gauge on each
    side, F = F0(d) + h s fitted by host/fitting/force.py), then force steps of
    5-10-15-10-5 N each way: the load's true force and the firmware's estimate both within 2 %
    of the target, the project's target (the paper: up to 7.0 % and 5.6 %). Without the friction
    term the same data leave the 5 N steps several % off, so this could fail."""
    from host.calibration.fixed_export import export_poly
    from host.fitting.force import fit_force
    from host.guided.force_identification import D_RANGE_MM, F_RANGE_N

    points = []
    for side in ("high", "low"):
        for d_um, f_mN, loading in on_cpython("case_force_points_sim(%r, %r, %r)" % (cal_path, side, [800, 1600, 2400, 3200, 4000, 4800])):
            if abs(f_mN) > 300:
                s = (1 if loading else -1) * (1 if side == "high" else -1)
                points.append((d_um / 1000.0, f_mN / 1000.0, s, loading))
    d, f, s, loading = (np.array(c) for c in zip(*points))
    fit = fit_force(d, f, s, "auto", loading=loading)
    plain = fit_force(d, f, s, fit.order_f, friction=False)
    assert 0.15 < fit.friction_n < 0.35 and fit.rms_n < plain.rms_n / 3, (fit, plain)
    path = tmp_path / "identified.json"
    model.write_model_calibration(
        path, friction={"kind": "friction", "fixed": [int(round(fit.friction_n * 1000))]},
        force={"kind": "poly", "fixed": list(export_poly(fit.coeffs_f, D_RANGE_MM[0], D_RANGE_MM[1], 1000, 1000))},
        force_inverse={"kind": "poly", "fixed": list(export_poly(fit.coeffs_d, F_RANGE_N[0], F_RANGE_N[1], 1000, 1000))})
    for side, sign in (("high", -1), ("low", 1)):
        call = "case_force_steps_sim(%r, %r, %r)" % (str(path), side, [sign * t for t in (5000, 10000, 15000, 10000, 5000)])
        here = on_cpython(call)
        assert here == on_micropython(call)
        for target, est, load in here:
            assert abs(load - target) <= 0.02 * abs(target), (side, here)
            assert abs(est - load) <= 0.02 * abs(load), (side, here)


def test_force_steps_on_a_spring_that_lifts_off_use_a_table_within_2_percent(tmp_path):
    """A spring pair whose preload (7 N) ends at 14.2 N, inside the paper's 15 N: the stiffness
    halves there. The force step's points (open-loop duty steps against the gauge, as the guided
    step takes them) get a free-knot table for F0(d) and its inverse, which the firmware evaluates
    with its pwl code; force steps of 5-10-15-10-5 N each way then stay within 2 % on both
    interpreters, where the best polynomial leaves several times the table's error."""
    from host.calibration.file import force_table_section
    from host.fitting.force import fit_force
    from host.guided.force_identification import D_RANGE_MM, F_RANGE_N

    board = model.sim_board()
    board["actuator"]["springs"].update({"k1_n_per_mm": 17.0, "k2_n_per_mm2": 0.28, "preload_n": 7.0})
    board_path = tmp_path / "kinked.json"
    board_path.write_text(json.dumps(board))
    path = tmp_path / "cal.json"
    model.write_model_calibration(path, board=board)
    points = []
    for side in ("high", "low"):
        call = "case_force_points_sim(%r, %r, %r, board_path=%r)" % (
            str(path), side, [650 * i for i in range(1, 9)], str(board_path))
        for d_um, f_mN, loading in on_cpython(call):
            if abs(f_mN) > 300:
                points.append((d_um / 1000.0, f_mN / 1000.0, (1 if loading else -1) * (1 if side == "high" else -1), loading))
    d, f, s, loading = (np.array(c) for c in zip(*points))
    fit = fit_force(d, f, s, "auto", loading=loading)
    poly_only = fit_force(d, f, s, "auto", tables=False)
    assert fit.kind == "pwl" and fit.rms_n * 3 < poly_only.rms_n, (fit.rms_n, poly_only.rms_n)
    identified = tmp_path / "identified.json"
    model.write_model_calibration(
        identified, board=board, friction={"kind": "friction", "fixed": [int(round(fit.friction_n * 1000))]},
        force=force_table_section(fit.knots_d, fit.knots_f, D_RANGE_MM, ("um", "mN")),
        force_inverse=force_table_section(fit.knots_f, fit.knots_d, F_RANGE_N, ("mN", "um")))
    for side, sign in (("high", -1), ("low", 1)):
        call = "case_force_steps_sim(%r, %r, %r, board_path=%r)" % (
            str(identified), side, [sign * t for t in (5000, 10000, 15000, 10000, 5000)], str(board_path))
        here = on_cpython(call)
        assert here == on_micropython(call)
        for target, est, load in here:
            assert abs(load - target) <= 0.02 * abs(target), (side, here)
            assert abs(est - load) <= 0.02 * abs(load), (side, here)


@pytest.mark.parametrize("pot", ["pot1", "pot2"])
def test_physical_wiper_lift_stops_motor_next_tick(cal_path, pot):
    call = "case_wiper_lift_sim(%r, %r)" % (cal_path, pot)
    assert on_cpython(call) == on_micropython(call)


def test_soft_stroke_limits_stop_short_of_the_end_stops_and_targets_inside_them_settle(cal_path):
    call = "case_stroke_limits_sim(%r)" % cal_path
    here = on_cpython(call)
    assert here == on_micropython(call)
    # full duty toward each end: stopped by the firmware within 0.3 mm of its limit (the
    # calibration's error and the stopping distance), never at the hard stops (0 and 60 mm)
    assert 59200 <= here["top_um"] <= 59800, here
    assert 200 <= here["bottom_um"] <= 800, here
    # a target 0.5 mm inside the limit, in the slow zone, is reached (pot 2's wiper travel)
    assert abs(here["held_um"] - here["target_um"]) <= 50, here


def test_run_in_real_time_on_sim_returns_with_motor_off():
    assert on_cpython("case_run_realtime_sim()") == on_micropython("case_run_realtime_sim()")


STICKY_TARGETS = [30000, 30500, 30300, 31000, 29700, 45000, 44950, 10000, 10020]  # the last: a 20 um step


@pytest.mark.parametrize("feed_forward", [True, False])
def test_position_on_a_sticky_block_parks_without_a_limit_cycle(tmp_path, feed_forward):
    """1.1 N of block friction (3.7x boards/sim.json's). With the friction's feed-forward duty the
    block reaches every target within the deadband's hysteresis (3 x 8 um) plus the calibration's
    error, settles in under 1.5 s, and then does not move at all (a limit cycle would); without
    it (an older calibration: friction alone) the PI leaves the block stuck short for seconds."""
    board = model.sim_board()
    board["actuator"]["block"]["coulomb_n"] = 1.1
    board_path = tmp_path / "sticky.json"
    board_path.write_text(json.dumps(board))
    path = tmp_path / "cal.json"
    model.write_model_calibration(path, board=board, feed_forward=feed_forward)
    call = "case_position_sticky_sim(%r, %r, %r)" % (str(path), str(board_path), STICKY_TARGETS)
    here = on_cpython(call)
    if feed_forward:
        assert here == on_micropython(call)
        assert here["moved_um"] <= 1 and here["true_err_um"] <= 30 and here["settle_ticks"] <= 1500, here
    else:
        assert here["true_err_um"] > 60 and here["settle_ticks"] > 1500, here


def test_force_mode_meets_a_slack_load_without_slamming_the_spring(cal_path):
    """Force mode switched on 2 mm short of the load: the block slides free with the spring at
    the friction force until the fibre takes it. The deformation setpoint waits while it leads
    the measured deformation (controller _DEFL_LEAD), so the integral has not wound up at contact
    and the spring stays near target + h (0.3 N on sim.json). Before the wait it peaked at
    8.3-8.7 N for a 5 N target (12 N from 5 mm)."""
    for side in ("high", "low"):
        call = "case_force_contact_sim(%r, %r, 5000, 2000)" % (cal_path, side)
        here = on_cpython(call)
        assert here == on_micropython(call)
        assert here["spring_peak_mN"] <= 5000 + 300 + 500, (side, here)


def test_the_force_setpoint_closes_on_its_goal_exponentially(cal_path):
    """[force-approach] (firmware/controller.py): the deformation setpoint ramps at defl_rate_um
    (2 um a step) and, once the ramp would reach its goal (the band edge) within the estimate's
    64-step average, closes on it exponentially with that time constant: away / 64 a step, so that
    the spring neither reaches the edge at speed nor overshoots it (the block follows the spring's
    peaks, which the average does not see). From 128 to 3 um ahead that takes 64 ln(128/3) = 240
    steps (at full speed 63, at half 125), from 16 to 3 um 107 (half speed: 14), none of more than
    1 um down to the goal itself (no last jump of defl_rate_um: 8 um at 250 Hz), and it gets there
    (1.5 s after the step it sits on its goal)."""
    for side in ("high", "low"):
        call = "case_force_approach_sim(%r, %r, 5000)" % (cal_path, side)
        here = on_cpython(call)
        assert here == on_micropython(call)
        assert here["near_steps"] >= 200 and here["end_steps"] >= 80 and here["largest_end_um"] == 1, (side, here)
        assert here["at_goal"], (side, here)


def test_friction_trim_brings_a_wrong_h_back_to_what_the_loop_meets(tmp_path):
    """The friction trim (host/guided/friction_trim.py) on the simulated actuator: the model's
    exact F0 with the block's friction (0.30 N in boards/sim.json) given as 0.45 N or 0.18 N.
    Force-mode holds at the trim's targets on both gauge sides (the real firmware against the
    simulated block and gauge), then the trim: both land within 60 mN of the simulated Coulomb
    friction, where they started 150 and 120 mN off."""
    from host.guided.friction_trim import SIDES, trim_magnitudes, trimmed_friction

    true_h = model.sim_board()["actuator"]["block"]["coulomb_n"]
    magnitudes = trim_magnitudes(16.0)
    for wrong in (0.45, 0.18):
        path = tmp_path / ("h%d.json" % round(wrong * 1000))
        model.write_model_calibration(path, friction={"kind": "friction", "fixed": [round(wrong * 1000)]})
        trim = trimmed_friction(wrong, _trim_holds(path, magnitudes, SIDES))
        assert not trim.why and abs(trim.friction_n - true_h) < 0.06, (wrong, trim)


def _trim_holds(path, magnitudes, sides):
    """The friction trim's holds on both gauge sides, as trimmed_friction takes them."""
    out = {}
    for side in ("high", "low"):
        sign = sides[side]
        rows = on_cpython("case_force_steps_sim(%r, %r, %r)" % (str(path), side, [sign * round(m * 1000) for m in magnitudes]))
        out[sign] = [(m, sign * est / 1000.0, sign * load / 1000.0) for m, (_, est, load) in zip(magnitudes, rows)]
    return out


def _worst_step_error(path, side, sign):
    """The paper's force steps (5, 10, 15, 10, 5 N) on `side`: the largest |load - target| / target."""
    rows = on_cpython("case_force_steps_sim(%r, %r, %r)" % (str(path), side, [sign * t for t in (5000, 10000, 15000, 10000, 5000)]))
    return max(abs(load - target) / abs(target) for target, _, load in rows)


def test_the_trim_corrects_an_f0_that_reads_3_percent_high(tmp_path):
    """The closed-loop F0 correction (host/fitting/force_correction.py) on the simulated actuator:
    the force sections a table of the model's spring scaled by 1.03, and h 0.40 N for the model's
    0.30 N. The loop then holds the load about 3 % short of the targets (checked on one side). The
    trim brings h back (the friction change and F0's error separated), its holds measure F0's error
    (2-5 % of each target, the two sides' mean), it writes the corrected F0 table and its inverse, and the same force
    steps then meet 2 % on both sides (1.1 % when written; 1.4 and 1.6 % with stop 44's half-rate
    end of the force ramp, when the bound went from 1.5 to 2 %; not measured apart with stop 45's
    exponential approach, [force-approach], which offline tallies on drawn actuators favour:
    docs/robustness.md, "Stop 45")."""
    from host.calibration.file import force_table_section, read_calibration, write_calibration
    from host.guided.friction_trim import SIDES, trim_magnitudes, trimmed_friction, trimmed_sections

    board = model.sim_board()
    true_h = board["actuator"]["block"]["coulomb_n"]
    cav = float(board["actuator"]["springs"]["cavity_mm"])
    d = np.linspace(-cav, cav, 41)
    f = 1.03 * model.spring_forces(board, d)
    path = tmp_path / "stiff.json"
    model.write_model_calibration(
        path, force=force_table_section(d, f, (-cav, cav), ("um", "mN")),
        force_inverse=force_table_section(f, d, (-25.0, 25.0), ("mN", "um")),
        friction={"kind": "friction", "friction_n": 0.40, "fit": {}, "fixed": [400]})
    before = _worst_step_error(path, "low", SIDES["low"])
    assert before > 0.025, before
    trim = trimmed_friction(0.40, _trim_holds(path, trim_magnitudes(16.0), SIDES))
    assert abs(trim.friction_n - true_h) < 0.06, trim
    # F0's error is what the two sides' holds share at each magnitude (about 3 %); what differs
    # between the sides is the friction and a few um of deformation at the anchor (30 mN each,
    # 0.6 % at 4.8 N: the model calibration's deformation offset moved one side's 4.8 N from
    # 2.0 to 0.9 % and the other's from 5.8 to 7.2 %, stop 55)
    assert not trim.f0.why, trim
    by_side = [dict(rows) for rows in trim.f0.errors.values()]
    assert len(by_side) == 2 and all(0.02 < (by_side[0][m] + by_side[1][m]) / 2 / m < 0.05 for m in by_side[0]), trim
    doc = read_calibration(path)
    sections, lines = trimmed_sections(doc, trim)
    assert set(sections) == {"friction", "force", "force_inverse"}, lines
    doc.update(sections)
    write_calibration(path, doc)
    after = {side: _worst_step_error(path, side, sign) for side, sign in SIDES.items()}
    assert max(after.values()) < 0.02, (before, after, lines)


def test_bench_gauge_reads_the_load_a_bench_would(cal_path, tmp_path):
    """The offline tallies' gauge (force_cases.BenchGauge: the gauge channel with its noise,
    display rounding and zero drift, tared with the fibre slack before and after the steps) against
    the simulator's true load over the same force steps, on a gauge whose zero drifts fast (6 N/min
    at most, about 1 N over a side's steps): the actuator's sign on both sides, and within 0.15 N
    of the truth (what the gauge's noise and the drift left after the interpolated tares allow;
    a reading without the tares or with the wrong sign misses by more)."""
    board = model.sim_board()
    board["actuator"]["gauge"].update(drift_n_per_min=6.0, drift_max_n=5.0)
    board_path = tmp_path / "drifting-gauge.json"
    board_path.write_text(json.dumps(board))
    for side, sign in (("high", -1), ("low", 1)):
        targets = [sign * t for t in (5000, 10000, 15000, 10000, 5000)]
        call = "case_force_steps_sim(%r, %r, %r, board_path=%r%%s)" % (cal_path, side, targets, str(board_path))
        true = on_cpython(call % "")
        measured = on_cpython(call % ", measured=True")
        for (target, _, load), (_, _, gauge) in zip(true, measured):
            assert gauge * target > 0 and abs(gauge - load) <= 150, (side, true, measured)
