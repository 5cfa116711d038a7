"""The closed-loop F0 correction (host/fitting/force_correction.py) and the sections the trim
writes with it (host/guided/friction_trim.py trimmed_sections): the error taken from the holds,
the corrected table, its inverse, and the holds it refuses."""

import math

import numpy as np

from host.calibration.file import poly_section
from host.fitting.force_correction import (F0Correction, common_errors, corrected_f0_table, deformation_span,
                                           f0_correction, f0_function)
from host.guided.friction_trim import Trim, trimmed_sections

SPRING = np.array([0.8, 0.0, 7.0, 0.1])  # N of mm: a hardening spring, 7 N/mm at rest, a little preload


def force_doc(coeffs=SPRING):
    d = np.linspace(-2, 2, 401)
    f = np.polyval(coeffs, d)
    return {"force": poly_section(coeffs, (-2.0, 2.0), 1000.0, 1000.0, ("um", "mN")),
            "force_inverse": poly_section(np.polyfit(f, d, 5), (-25.0, 25.0), 1000.0, 1000.0, ("mN", "um")),
            "friction": {"kind": "friction", "friction_n": 0.4, "feed_forward_duty": 0, "fit": {}, "fixed": [400]}}


def test_the_friction_change_cancels_between_a_loading_and_an_unloading_hold():
    rows = [(4.8, 4.9, 4.8, True), (9.6, 9.5, 9.6, True), (14.4, 14.5, 14.4, True), (9.6, 9.8, 9.6, False),
            (4.8, 5.0, 4.8, False)]
    errors = common_errors(rows, 0.05)  # h grew by 50 mN: loading estimates fall by it, unloading ones rise
    assert [m for m, _ in errors] == [4.8, 9.6, 14.4]
    assert np.allclose([c for _, c in errors], [(0.05 + 0.25) / 2, (-0.15 + 0.25) / 2, 0.05]), errors


def test_the_correction_is_a_line_from_zero_through_the_holds_and_flat_beyond_on_each_side():
    c = F0Correction({1: [(4.0, 0.08), (8.0, -0.04)], -1: [(5.0, 0.10)]})
    got = c.at([2.0, 4.0, 6.0, 8.0, 12.0, -2.5, -5.0, -9.0, 0.0])
    # on the negative side an error of +0.10 in magnitude is -0.10 in the force's own sign
    assert np.allclose(got, [0.04, 0.08, 0.02, -0.04, -0.04, -0.05, -0.10, -0.10, 0.0]), got


def test_an_error_beyond_10_percent_and_300_mN_is_refused():
    assert not f0_correction({1: [(4.8, 0.45)]}).why  # 9.4 %
    assert not f0_correction({1: [(2.0, 0.29)]}).why  # 14.5 %, but under 300 mN
    refused = f0_correction({1: [(4.8, 0.10)], -1: [(9.6, -1.0)]})
    assert "-1000 mN at -9.6 N" in refused.why, refused
    assert f0_correction({1: [], -1: []}).why == "no hold with a taut fibre"


def test_the_corrected_table_is_f0_less_the_error_and_follows_f0_where_the_error_is_zero():
    section = force_doc()["force"]
    f0 = f0_function(section)
    span = deformation_span(section, (-2.0, 2.0), (-25.0, 25.0))
    assert span == (-2.0, 2.0) and f0(-2.0) > -25 and f0(2.0) < 25  # F0 rises over the whole cavity
    correction = F0Correction({1: [(4.8, 0.1), (9.6, 0.1), (14.4, 0.2)], -1: [(4.8, -0.05)]})
    kd, kf = corrected_f0_table(section, span, correction)
    assert np.all(np.diff(kd) > 0) and np.all(np.diff(kf) > 0)
    d = np.linspace(kd[0], kd[-1], 997)
    want = f0(d) - correction.at(f0(d))
    assert np.max(np.abs(np.interp(d, kd, kf) - want)) < 0.003  # TABLE_TOL_N, plus the kink of c at each hold
    nothing = corrected_f0_table(section, span, F0Correction({1: [], -1: []}))
    assert np.max(np.abs(np.interp(d, *nothing) - f0(d))) <= 0.002


def test_a_side_the_gauge_never_loaded_keeps_its_f0():
    section = force_doc()["force"]
    f0 = f0_function(section)
    kd, kf = corrected_f0_table(section, deformation_span(section, (-2.0, 2.0), (-25.0, 25.0)),
                                F0Correction({1: [(4.8, 0.1), (14.4, 0.1)]}))
    d = np.linspace(-2.0, -0.05, 300)  # F0 < 0 there: the high side, never loaded
    assert np.max(np.abs(np.interp(d, kd, kf) - f0(d))) <= 0.002


def test_the_span_stops_where_f0_folds_back_or_leaves_the_force_range():
    folding = poly_section([-3.0, 0.0, 7.0, 0.0], (-2.0, 2.0), 1000.0, 1000.0, ("um", "mN"))  # peaks at +-0.88 mm
    lo, hi = deformation_span(folding, (-2.0, 2.0), (-25.0, 25.0))
    assert math.isclose(lo, -math.sqrt(7 / 9), abs_tol=0.002) and math.isclose(hi, math.sqrt(7 / 9), abs_tol=0.002)
    lo, hi = deformation_span(force_doc()["force"], (-2.0, 2.0), (-10.0, 10.0))
    f0 = f0_function(force_doc()["force"])
    assert -9.0 <= f0(lo) < -8.9 and 8.9 < f0(hi) <= 9.0, (f0(lo), f0(hi))  # 90 % of it (SPAN_OF_RANGE)
    offset = poly_section([7.0, 3.0], (-2.0, 2.0), 1000.0, 1000.0, ("um", "mN"))  # 3 N at d = 0: crosses at -0.43
    assert deformation_span(offset, (-2.0, 2.0), (-25.0, 25.0))[0] == -2.0
    try:
        deformation_span(poly_section([7.0, 20.0], (-2.0, 2.0), 1000.0, 1000.0, ("um", "mN")), (-2.0, 2.0), (-25.0, 25.0))
        raise AssertionError("a spring that never crosses 0 N in the cavity has no span")
    except ValueError as exc:
        assert "does not rise through 0 N" in str(exc)


def test_trimmed_sections_write_h_and_an_f0_table_with_its_exact_inverse():
    doc = force_doc()
    correction = F0Correction({1: [(4.8, 0.06), (9.6, -0.03)], -1: [(4.8, 0.02)]})
    trim = Trim(0.45, 20.0, -80.0, 10, f0=correction)
    sections, lines = trimmed_sections(doc, trim)
    assert sections["friction"]["friction_n"] == 0.45 and sections["friction"]["fit"]["identified_n"] == 0.4
    force, inverse = sections["force"], sections["force_inverse"]
    assert force["kind"] == inverse["kind"] == "pwl"
    assert force["knots_in"] == inverse["knots_out"] and force["knots_out"] == inverse["knots_in"]
    assert math.isclose(np.interp(0.0, force["knots_in"], force["knots_out"]), 0.1, abs_tol=0.003)
    d = float(np.interp(4.8, force["knots_out"], force["knots_in"]))  # where the corrected F0 reads 4.8 N
    assert math.isclose(f0_function(doc["force"])(d), 4.86, abs_tol=0.005)  # the old F0 read 60 mN more there
    d = float(np.interp(-4.8, force["knots_out"], force["knots_in"]))
    assert math.isclose(f0_function(doc["force"])(d), -4.82, abs_tol=0.005)  # 20 mN more in magnitude on that side
    assert force["fit"]["identified"]["coefficients"] == doc["force"]["coefficients"]  # the identified F0 is kept
    assert "F0 corrected in closed loop" in lines[-1] and "+4.8 N: +60 mN" in lines[-1], lines


def test_a_refused_correction_still_trims_h_and_says_why_f0_was_kept():
    doc = force_doc()
    trim = Trim(0.45, 20.0, -80.0, 10, f0=F0Correction({1: [(4.8, 0.6)]}, why="too large"))
    sections, lines = trimmed_sections(doc, trim)
    assert set(sections) == {"friction"} and "F0 not corrected (too large)" in lines[-1], lines
    # a table the board would refuse is not written: here a poly F0 that never crosses 0 N
    doc_far = dict(doc, force=poly_section([7.0, 20.0], (-2.0, 2.0), 1000.0, 1000.0, ("um", "mN")))
    sections, lines = trimmed_sections(doc_far, Trim(0.45, 20.0, -80.0, 10, f0=F0Correction({1: [(4.8, 0.05)]})))
    assert set(sections) == {"friction"} and "F0 not corrected (F0 does not rise through 0 N" in lines[-1], lines
    kept = Trim(0.4, 0.0, 0.0, 2, why="no target held both loading and unloading")
    assert trimmed_sections(doc, kept)[0] == {} and kept.f0.why


def test_knots_closer_than_the_firmwares_units_are_merged():
    """The firmware's tables hold um and mN, and refuse a step of 0 (a table must rise). Knots the
    table keeps (an old table's, where the correction turns) can land within a micrometre of each
    other: here an old table's two knots 0.3 um apart."""
    from host.calibration.file import check_sections, force_table_section

    section = {"kind": "pwl", "knots_in": [-1.5, -0.5, 0.5, 0.5003, 1.5], "knots_out": [-14.0, -4.0, 4.5, 4.503, 16.0]}
    kd, kf = corrected_f0_table(section, deformation_span(section, (-2.0, 2.0), (-25.0, 25.0)),
                                F0Correction({1: [(4.8, 0.05)], -1: [(4.8, -0.03)]}))
    assert np.all(np.diff(np.round(kd * 1000)) > 0) and np.all(np.diff(np.round(kf * 1000)) > 0)
    check_sections({"force": force_table_section(kd, kf, (-2.0, 2.0), ("um", "mN")),
                    "force_inverse": force_table_section(kf, kd, (-25.0, 25.0), ("mN", "um"))})


def test_a_spring_that_reaches_the_inverses_range_leaves_it_a_whole_segment():
    """The exporter carries the table's last segment on to the inverse's +-25 N. A table that ended
    at 24.99 N left a segment of a fraction of a micrometre, a step of 0 um the board refuses (a
    full robustness run stopped there): the span stops at 90 % of the range. Springs of 12-13 N/mm
    that reach 25 N inside the cavity."""
    from host.calibration.file import check_sections, force_table_section

    for k in np.linspace(12.0, 13.0, 12):
        section = {"kind": "poly", "coefficients": [0.8, 0.0, k, 0.1]}
        kd, kf = corrected_f0_table(section, deformation_span(section, (-2.0, 2.0), (-25.0, 25.0)),
                                    F0Correction({1: [(4.8, 0.05)]}))
        assert kf[-1] <= 22.5
        check_sections({"force": force_table_section(kd, kf, (-2.0, 2.0), ("um", "mN")),
                        "force_inverse": force_table_section(kf, kd, (-25.0, 25.0), ("mN", "um"))})


def test_a_table_the_board_would_refuse_is_not_written(monkeypatch):
    """Should a corrected table still be one the board refuses (here: the span's 90 % rule undone,
    the slivers of the test above back), the trim keeps the identified F0 and says why, and the
    run goes on: before, such a file stopped a whole robustness run at its calibration."""
    import host.fitting.force_correction as force_correction

    monkeypatch.setattr(force_correction, "SPAN_OF_RANGE", 1.0)
    refused = 0
    for k in np.linspace(12.0, 13.0, 12):
        doc = dict(force_doc(), force=poly_section([0.8, 0.0, k, 0.1], (-2.0, 2.0), 1000.0, 1000.0, ("um", "mN")))
        sections, lines = trimmed_sections(doc, Trim(0.45, 0.0, 0.0, 10, f0=F0Correction({1: [(4.8, 0.05)]})))
        if "F0 not corrected (section force_inverse: a force table must rise)" in lines[-1]:
            refused += 1
            assert set(sections) == {"friction"}, sections
        else:
            assert "F0 corrected" in lines[-1], lines
    assert refused > 0


def test_a_corrected_table_is_capped_at_its_knots_and_refused_when_it_then_strays(monkeypatch):
    """An F0 polynomial fitted to few levels can bend enough that following F0 - c within 2 mN took
    hundreds of knots: a CI run's calibration grew to 68 KB, which the board refuses. The table
    stops at MAX_TABLE_KNOTS, a few mN off; should that leave more than MAX_STRAY_N, the correction
    is refused and the identified F0 kept."""
    import host.fitting.force_correction as force_correction

    wild = poly_section([3.0, 0.0, -4.0, 0.0, 8.0, 0.1], (-2.0, 2.0), 1000.0, 1000.0, ("um", "mN"))
    correction = F0Correction({1: [(4.8, 0.05)]})
    span = deformation_span(wild, (-2.0, 2.0), (-25.0, 25.0))
    kd, kf = corrected_f0_table(wild, span, correction)
    assert len(kd) == force_correction.MAX_TABLE_KNOTS
    d = np.linspace(span[0], span[1], 3001)
    f = f0_function(wild)(d)
    assert np.max(np.abs(np.interp(d, kd, kf) - (f - correction.at(f)))) < force_correction.MAX_STRAY_N
    doc = dict(force_doc(), force=wild)
    sections, lines = trimmed_sections(doc, Trim(0.45, 0.0, 0.0, 10, f0=correction))
    assert "F0 corrected in closed loop" in lines[-1] and "128-knot table" in lines[-1], lines

    monkeypatch.setattr(force_correction, "MAX_TABLE_KNOTS", 8)  # too few for any spring's bend
    sections, lines = trimmed_sections(force_doc(), Trim(0.45, 0.0, 0.0, 10, f0=correction))
    assert set(sections) == {"friction"} and "F0 bends too much to tabulate" in lines[-1], lines


def test_a_calibration_larger_than_the_board_reads_is_never_written(tmp_path, monkeypatch):
    """The board refuses a calibration file over firmware.calibration.MAX_BYTES at boot. The writer
    refuses to make one (the old file stays), and the trim, which checks its sections as the board
    will, keeps the identified F0 and says why instead of stopping the run at the flash."""
    import pytest

    import host.fitting.force_correction as force_correction
    from firmware.calibration import MAX_BYTES
    from host.calibration.file import write_calibration
    from host.errors import UserError

    monkeypatch.setattr(force_correction, "MAX_TABLE_KNOTS", 2001)  # every point of the dense grid
    monkeypatch.setattr(force_correction, "TABLE_TOL_N", 1e-9)
    sections, lines = trimmed_sections(force_doc(), Trim(0.45, 0.0, 0.0, 10, f0=F0Correction({1: [(4.8, 0.05)]})))
    assert set(sections) == {"friction"}, lines
    assert "F0 not corrected (the calibration would be" in lines[-1] and "more than the %d" % MAX_BYTES in lines[-1], lines

    path = tmp_path / "calibration.json"
    path.write_text("the old calibration")
    huge = np.linspace(-2.0, 2.0, 1500)
    from host.calibration.file import force_table_section

    doc = dict(force_doc(), force=force_table_section(huge, 7.0 * huge, (-2.0, 2.0), ("um", "mN")))
    with pytest.raises(UserError, match="more than the %d the board reads" % MAX_BYTES):
        write_calibration(path, doc)
    assert path.read_text() == "the old calibration"
