"""host/calibration/consistency.py: a pot section's readable knots against its table. A table the
export made from the fit's own knots must list about as many knots as it has (a truncated list
is refused: tests/link/test_flash.py); one the export had to sample from the fit's curve
(export_curve_table, when the knots themselves cannot be exported) has as many knots as it
needed, so only the positions at the listed knots are compared."""

import numpy as np

from host.calibration.consistency import contradictions
from host.calibration.file import pot_section
from host.fitting.piecewise_linear import _result

BOARD = {"adc_bits": 12}


def pwl_fit(kx, ky):
    fit = _result("pwl", len(kx), len(kx), np.asarray(kx, dtype=float), np.asarray(ky, dtype=float))
    fit.monotone = True
    return fit


def test_a_table_sampled_from_the_fit_is_judged_by_its_positions_not_its_knot_count():
    # two knot codes closer than the table's resolution, 5 um apart (knots there with one value are
    # merged: tests/firmware/test_pwl_fixed.py): the knots cannot be a table, the curve can
    kx = [0.0, 1e-6, 1000.0, 2000.0, 3000.0, 4095.0]
    ky = [0.0, 0.005, 15.0, 30.0, 45.0, 60.0]
    section = pot_section(pwl_fit(kx, ky), 12)
    assert section["fixed_check"].get("sampled") is True and section["fixed"][0] > len(kx) + 3
    assert contradictions({"board": "sim", "pot1": section}, BOARD) == []
    # its listed positions must still agree with what the table gives
    wrong = dict(section, coefficients=dict(section["coefficients"], knots_y=[0.0, 0.0, 15.0, 31.0, 45.0, 60.0]))
    said = contradictions({"board": "sim", "pot1": wrong}, BOARD)
    assert len(said) == 1 and "knots say 31 mm" in said[0], said


def test_a_table_of_the_fits_own_knots_must_list_them_all():
    kx = [0.0, 1000.0, 2000.0, 3000.0, 4095.0]
    ky = [0.0, 15.0, 30.0, 45.0, 60.0]
    section = pot_section(pwl_fit(kx, ky), 12)
    assert "sampled" not in section["fixed_check"]
    assert contradictions({"board": "sim", "pot1": section}, BOARD) == []
    dense = [float(v) for v in np.linspace(0, 4095, 20)]
    listed = dict(section, coefficients={"knots_x": dense, "knots_y": [v * 60 / 4095 for v in dense]})
    said = contradictions({"board": "sim", "pot1": listed}, BOARD)
    assert len(said) == 1 and "lists 20 knots for a table of" in said[0], said


def test_a_long_line_split_by_the_export_lists_its_two_knots_and_a_bent_table_cannot():
    # a 2-point line over 80 mm: the export splits it (each segment's interpolation product must
    # stay within 31 bits) into more knots than EXTRA_KNOTS pads, all on the line
    section = pot_section(pwl_fit([10.0, 4085.0], [-27.0, 65.0]), 12)
    assert section["fixed"][0] > 2 + 3
    assert contradictions({"board": "sim", "pot1": section}, BOARD) == []
    # the same count of extra knots off the line is a truncated list
    kx = [float(v) for v in np.linspace(10, 4085, 8)]
    bent = pot_section(pwl_fit(kx, [-27.0 + 92.0 * (x / 4095) ** 1.3 for x in kx]), 12)
    ends = dict(bent, coefficients={"knots_x": [kx[0], kx[-1]], "knots_y": [bent["coefficients"]["knots_y"][0],
                                                                           bent["coefficients"]["knots_y"][-1]]})
    said = contradictions({"board": "sim", "pot1": ends}, BOARD)
    assert len(said) == 1 and "lists 2 knots for a table of" in said[0], said


def test_knots_between_two_codes_are_judged_against_both_codes_positions():
    """A fitted pot whose knee put two knots 0.28 codes and 0.29 mm apart (the knots of seed
    202611271100's pot 2, whose calibration the flash refused mid-experiment): the board reads
    whole codes, so a knot between codes 185 and 186 agrees with any position between theirs."""
    kx = [180.0, 185.18914838728105, 185.46976832190026, 197.8841414382282, 222.57965257317647, 268.14660068754444,
          339.5715163072671, 429.4444128742105, 3478.280123310009, 3601.980515725182, 3698.697408941289, 3768.0]
    ky = [-0.17401954651221424, -0.16334934074488866, 0.13153991936401982, 0.9459514186352943, 1.9558155566553301,
          3.2009536912052563, 4.623333200649134, 6.008077921147455, 44.94693498081846, 46.739171152372194,
          48.3502691498051, 49.70890783523511]
    section = pot_section(pwl_fit(kx, ky), 12)
    assert contradictions({"board": "sim", "pot2": section}, BOARD) == []
    # a knot 0.3 mm beyond both neighbouring codes' positions is still a contradiction
    wrong = dict(section, coefficients=dict(section["coefficients"], knots_y=ky[:2] + [ky[2] + 0.3] + ky[3:]))
    said = contradictions({"board": "sim", "pot2": wrong}, BOARD)
    assert len(said) == 1 and "knots say 0.43154 mm at code 185.47, its table gives" in said[0], said
