"""Checks a pot sweep must pass before its fit is offered: each says what to do when it fails.

All work on plain arrays (raw codes, reference mm, direction +1/-1) so they can be tested on
synthetic data: range covered, monotone, noise level, rail-clipped samples, forward/backward
hysteresis, and the end stops' distance. Limits are for a 60 mm stroke measured by a 12-bit ADC;
the guided calibration sets the range and the stops' distance to its actuator's stroke
(host/guided/flow.py follow_the_actuator) and, where the pots step measured the end stops, the
range to 90 % of their distance as that pot's reference read them (pot_calibration.sweep_limits:
the sweep includes the still records at the stops, so there the stops check is the one that
can fail).
"""

from dataclasses import dataclass

import numpy as np

from host.fitting.noise_floor import estimate_hysteresis, estimate_noise


@dataclass
class Check:
    name: str
    ok: bool
    value: float
    limit: float
    unit: str
    advice: str  # what to do when it fails

    def line(self):
        mark = "ok  " if self.ok else "FAIL"
        text = "%s %-10s %8.4g %s (limit %.4g)" % (mark, self.name, self.value, self.unit, self.limit)
        return text if self.ok else text + ": " + self.advice


@dataclass
class Limits:
    min_range_mm: float = 54.0  # 90 % of the stroke (here the 0-60 mm one's)
    # the block's end stops at least this far apart as the reference on a pot reads them (80 % of
    # the 0-60 mm stroke): a pot's mount stretches or shrinks its scale by some per cent, a block
    # that jams part-way shows far less
    min_stops_mm: float = 48.0
    # a pot with 5 LSB of noise read 4x (oversample) shows ~0.05 mm rms over a 60 mm stroke, more
    # where its curve is flat; broken wiring or a noisy supply shows several times that
    max_noise_mm: float = 0.1
    max_rail_fraction: float = 0.0
    max_hysteresis_mm: float = 0.1
    max_backsteps: float = 0.01  # fraction of binned reference steps going the wrong way
    bins: int = 60


def check_range(y, limits):
    span = float(np.max(y) - np.min(y)) if len(y) else 0.0
    return Check("range", span >= limits.min_range_mm, span, limits.min_range_mm, "mm",
                 "the sweep did not cover the stroke: check that the block runs end to end freely, that the "
                 "reference sensor follows it, and that the reference scale (--ref-zero-mm/--ref-span-mm) is right")


def check_stops(span_mm, limits):
    """The distance between the block's two end stops as the reference on one pot read them."""
    return Check("stops", span_mm >= limits.min_stops_mm, span_mm, limits.min_stops_mm, "mm",
                 "the block's end stops are closer than the stroke allows: check that nothing jams the block "
                 "part-way, that the board file's stroke_mm is this actuator's, and that the reference scale "
                 "(--ref-zero-mm/--ref-span-mm) is right")


def check_monotone(x, y, limits, noise):
    """Bin by raw code; the bin means of the reference must not go down by more than the noise
    allows (a pot mounted on the wrong axis or a slipping coupling makes them)."""
    order = np.argsort(x, kind="stable")
    xs, ys = x[order], y[order]
    edges = np.linspace(xs[0], xs[-1], limits.bins + 1)
    idx = np.clip(np.searchsorted(edges, xs, side="right") - 1, 0, limits.bins - 1)
    counts = np.bincount(idx, minlength=limits.bins)
    sums = np.bincount(idx, weights=ys, minlength=limits.bins)
    means = sums[counts > 0] / counts[counts > 0]
    steps = np.diff(means)
    tol = 4.0 * max(noise, 1e-3)
    back = float(np.count_nonzero(steps < -tol)) / max(len(steps), 1)
    return Check("monotone", back <= limits.max_backsteps, back, limits.max_backsteps, "of steps backwards",
                 "the reference does not rise with the pot: is the reference mounted on THIS pot, "
                 "is its coupling tight, are pot and reference wired the same way round?")


def check_noise(noise, limits):
    return Check("noise", noise <= limits.max_noise_mm, noise, limits.max_noise_mm, "mm rms",
                 "too noisy: check grounding and the pot's supply, shorten or shield the wires, raise "
                 "\"oversample\" in the board file")


def check_rails(raw, adc_bits, limits):
    full = (1 << adc_bits) - 1
    frac = float(np.count_nonzero((raw <= 0) | (raw >= full))) / max(len(raw), 1)
    return Check("rails", frac <= limits.max_rail_fraction, frac, limits.max_rail_fraction, "of samples at a rail",
                 "samples clipped at 0 or full scale: a wiper lifts off or the pot's end is outside the ADC "
                 "range; check the wiper contact and the pot's supply/reference voltage")


def check_hysteresis(hyst, limits):
    return Check("hysteresis", abs(hyst) <= limits.max_hysteresis_mm, abs(hyst), limits.max_hysteresis_mm, "mm",
                 "forward and backward runs disagree: backlash between pot and reference; tighten the "
                 "coupling and sweep slower (--duty)")


def check_sweep(raw, ref_mm, direction, adc_bits, limits=None):
    """Every check on one sweep; returns (list of Check, noise mm, hysteresis mm)."""
    limits = limits or Limits()
    x = np.asarray(raw, dtype=float)
    y = np.asarray(ref_mm, dtype=float)
    d = None if direction is None else np.asarray(direction)
    if len(x) < 20:
        return [Check("samples", False, float(len(x)), 20, "samples", "almost no data: did the motor run?")], float("nan"), 0.0
    inside = (x > 0) & (x < (1 << adc_bits) - 1)
    try:
        noise = estimate_noise(x[inside], y[inside], None if d is None else d[inside])
    except ValueError:
        noise = float("inf")
    hyst = estimate_hysteresis(x[inside], y[inside], None if d is None else d[inside]) if d is not None else 0.0
    checks = [
        check_range(y, limits),
        check_monotone(x[inside], y[inside], limits, noise),
        check_noise(noise, limits),
        check_rails(x, adc_bits, limits),
        check_hysteresis(hyst, limits),
    ]
    return checks, noise, hyst
