"""Calibration files for the "before" halves of the experiments, derived from the real one.

- nominal: each pot as a straight line through its two end readings (a 2-point pwl table: what
  one gets from a pot's datasheet and the stroke ends, without the BCM), no Df, no force.
- without Df: the accepted calibration with Df_hat = 0 (the firmware's force mode needs a df
  section, so "no Df correction" is a zero polynomial, not a missing one).
"""

import numpy as np

from host.calibration.file import poly_section, pot_section, read_calibration, write_calibration
from host.fitting.models import fit_model


def nominal_pot_section(raw, ref_mm, adc_bits, pot):
    """2-point line from the lowest to the highest reading of the sweep (ends of the stroke)."""
    raw = np.asarray(raw, dtype=float)
    ref = np.asarray(ref_mm, dtype=float)
    lo, hi = np.argmin(raw), np.argmax(raw)
    x = np.linspace(raw[lo], raw[hi], 64)
    y = np.interp(x, [raw[lo], raw[hi]], [ref[lo], ref[hi]])
    fit = fit_model("pwl", x, y, 2)
    return pot_section(fit, adc_bits, pot_id=pot)


def write_nominal(path, calibrated_path, pot_data, adc_bits):
    doc = read_calibration(calibrated_path)
    nominal = {k: doc[k] for k in ("schema", "board", "pots", "date") if k in doc}
    for pot in ("pot1", "pot2"):
        nominal[pot] = nominal_pot_section(pot_data[pot]["raw"], pot_data[pot]["ref"], adc_bits, pot)
    write_calibration(path, nominal)
    return path


def write_without_df(path, calibrated_path):
    doc = read_calibration(calibrated_path)
    x_range = doc["df"].get("x_range") or doc["df"]["in_range"]
    doc["df"] = poly_section([0.0], x_range, 1000.0, 1000.0, ("um", "um"), {"note": "Df correction off"})
    write_calibration(path, doc)
    return path
