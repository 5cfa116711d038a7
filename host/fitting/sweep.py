"""A calibration sweep: pairs of (pot reading `raw`, true position `reference`), cleaned for fitting.

A sweep CSV has a header row with at least the columns `raw` and `reference`; an optional
`direction` column (+1 / -1, the direction of motion) is kept for hysteresis-aware noise
estimates; every other column is ignored. Hygiene, each step counted in `Sweep.exclusions`:

- rows whose raw or reference is not a finite number are dropped ("non_finite"); a number beyond
  +-MAX_MAGNITUDE refuses the sweep;
- rows clipped at an end are dropped ("clipped_low" / "clipped_high"): two or more rows that
  share the lowest (or highest) raw value AND either sit on a rail of the converter (0 or its
  full scale, when that is known: given, or guessed for ADC codes) or have a reference that kept
  moving while raw stood still (further than the sweep's noise and one raw step explain). Such
  rows do not belong to the function raw -> reference. Ties without either sign are repeated
  readings of a slow sweep and stay;
- the rest is sorted by raw (stable, so equal codes keep their file order).

A sweep that has too few good points, or covers too little of its range, is refused with a
`UserError`, because no calibration fitted to it could be trusted over the whole stroke.
"""

import csv
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from host.errors import UserError, check_user_file
from host.fitting.noise_floor import estimate_noise

MIN_POINTS = 20  # fewer cannot pin down a 7-parameter BCM-3 with any redundancy
MIN_COVERAGE = 0.25  # of the ADC full scale, when raw looks like ADC codes
MAX_GAP = 0.25  # largest empty stretch between readings, as a share of the covered span
ADC_FULL_SCALES = (1023, 4095, 16383, 65535)  # 10, 12, 14, 16 bit
# Larger numbers are no pot's reading or position (60 mm in nm is 6e7), and near 1e300 the fits'
# sums of squares overflow: tracebacks and warnings instead of a result
MAX_MAGNITUDE = 1e12


@dataclass
class Sweep:
    x: np.ndarray  # raw readings, cleaned and sorted
    y: np.ndarray  # reference values in the same order
    direction: object  # np.ndarray of +1/-1 in the same order, or None
    n_input: int  # data rows in the file (or arrays given)
    n_excluded: int  # rows hygiene removed
    exclusions: dict = field(default_factory=dict)  # reason -> count (only reasons that occurred)
    path: object = None  # the file it came from, or None

    def describe(self):
        """One line: how many points were kept and why the others were not."""
        dropped = ", ".join("%d %s" % (n, k.replace("_", " ")) for k, n in self.exclusions.items())
        return "%d of %d rows kept%s" % (len(self.x), self.n_input, " (excluded: %s)" % dropped if dropped else "")


def _number(text, column, line, path):
    try:
        value = float(text)
    except (TypeError, ValueError):
        raise UserError("line %d of %s: %s value %r is not a number" % (line, path, column, text)) from None
    if abs(value) > MAX_MAGNITUDE and math.isfinite(value):  # non-finite rows are dropped below
        raise UserError("line %d of %s: %s value %s is beyond +-%g: not a reading or a position in any unit"
                        % (line, path, column, text, MAX_MAGNITUDE))
    return value


MAX_SWEEP_BYTES = 256 << 20  # millions of rows: far beyond any sweep, short of filling the memory


def load_sweep(path, full_scale=None):
    """Read and clean a sweep CSV (see the module docstring); raises UserError on bad input.

    `full_scale`: the converter's full scale in raw units (e.g. 3.3 for volts); by default it is
    guessed only when raw looks like ADC codes, and without it there is no coverage check."""
    path = Path(path)
    check_user_file(path, "sweep file", MAX_SWEEP_BYTES)
    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:
            rows = list(csv.reader(fh))
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise UserError("cannot read sweep %s: %s" % (path, exc)) from None
    rows = [r for r in rows if any(cell.strip() for cell in r)]
    if not rows:
        raise UserError("sweep %s is empty (expected a header with raw,reference and data rows)" % path)
    header = [h.strip().lower() for h in rows[0]]
    for needed in ("raw", "reference"):
        if needed not in header:
            raise UserError("sweep %s has no %r column (header: %s)" % (path, needed, ",".join(header)))
    ix, iy = header.index("raw"), header.index("reference")
    idir = header.index("direction") if "direction" in header else None
    raw, ref, direction = [], [], []
    for line, row in enumerate(rows[1:], start=2):
        cells = [c.strip() for c in row]
        if len(cells) <= max(ix, iy, idir if idir is not None else 0):
            raise UserError("line %d of %s has %d fields, the header has %d" % (line, path, len(cells), len(header)))
        raw.append(_number(cells[ix], "raw", line, path))
        ref.append(_number(cells[iy], "reference", line, path))
        if idir is not None:
            d = _number(cells[idir], "direction", line, path)
            if d not in (1.0, -1.0):
                raise UserError("line %d: direction must be +1 or -1, not %r" % (line, cells[idir]))
            direction.append(d)
    if not raw:
        raise UserError("sweep %s has a header but no data rows" % path)
    sweep = sweep_from_arrays(raw, ref, direction if idir is not None else None, source=str(path),
                              full_scale=full_scale)
    sweep.path = path
    return sweep


def _full_scale(x):
    """The ADC full scale the readings look like, or None when they are not ADC codes."""
    lo, hi = float(np.min(x)), float(np.max(x))
    if lo < 0 or hi < 256:  # volts, millimetres, or an 8-bit-or-less converter: no claim
        return None
    for fs in ADC_FULL_SCALES:
        if hi <= fs:
            return fs
    return None


def adc_bits_of(x):
    """The ADC width (bits) that raw readings `x` imply, or None when they do not look like ADC
    codes (then the width must be given to write a calibration)."""
    fs = _full_scale(x)
    return None if fs is None else fs.bit_length()


def sweep_from_arrays(raw, reference, direction=None, source="sweep", full_scale=None):
    """Apply the sweep hygiene to arrays already in memory; returns a Sweep (path None)."""
    x = np.asarray(raw, dtype=float).ravel()
    y = np.asarray(reference, dtype=float).ravel()
    if x.shape != y.shape:
        raise UserError("%s: raw has %d values but reference has %d" % (source, x.size, y.size))
    if full_scale is not None and not (math.isfinite(full_scale) and full_scale > 0):
        raise UserError("%s: the full scale must be a positive number, not %r" % (source, full_scale))
    d = None if direction is None else np.asarray(direction, dtype=float).ravel()
    if d is not None:
        if d.shape != x.shape:
            raise UserError("%s: direction has %d values, raw has %d" % (source, d.size, x.size))
        if not np.all((d == 1) | (d == -1)):
            raise UserError("%s: direction values must all be +1 or -1" % source)
    n_input = int(x.size)
    exclusions = {}
    keep = np.isfinite(x) & np.isfinite(y)
    if not np.all(keep):
        exclusions["non_finite"] = int(np.count_nonzero(~keep))
    fs = _full_scale(x[keep]) if full_scale is None and np.any(keep) else full_scale
    if np.count_nonzero(keep) >= 2:
        xs = x[keep]
        ties = {reason: keep & (x == end) for reason, end in (("clipped_low", np.min(xs)), ("clipped_high", np.max(xs)))}
        for reason, at_end in ties.items():
            # one reading at the end may be a real end point; two or more are clipped only with a sign
            if np.count_nonzero(at_end) >= 2 and _clipped(x, y, keep & ~ties["clipped_low"] & ~ties["clipped_high"],
                                                          at_end, fs):
                exclusions[reason] = int(np.count_nonzero(at_end))
                keep &= ~at_end
    x, y = x[keep], y[keep]
    d = None if d is None else d[keep]
    order = np.argsort(x, kind="stable")
    x, y = x[order], y[order]
    d = None if d is None else d[order]
    _check_usable(x, y, n_input, source, fs)
    return Sweep(x=x, y=y, direction=d, n_input=n_input, n_excluded=n_input - int(x.size), exclusions=exclusions)


def _clipped(x, y, inner, at_end, fs):
    """Whether the rows `at_end` (two or more sharing the lowest or highest raw) are clipped: on a
    rail of the converter, or with a reference that moved further than noise and one raw step."""
    end = float(x[at_end][0])
    if fs is not None and (end <= 0 or end >= fs):
        return True
    xi, yi = x[inner], y[inner]
    if xi.size < 3:
        return False
    noise = estimate_noise(xi, yi)  # direction-blind: hysteresis between passes counts as noise
    step = float(np.min(np.diff(np.unique(xi))))  # the raw resolution (1 for ADC codes)
    near = np.argsort(np.abs(xi - end), kind="stable")[:10]  # the local slope next to this end
    slope = abs(np.polyfit(xi[near], yi[near], 1)[0]) if np.ptp(xi[near]) > 0 else 0.0
    return float(np.ptp(y[at_end])) > 4 * noise + 3 * slope * step


def _check_usable(x, y, n_input, source, fs):
    n = int(x.size)
    if n < MIN_POINTS:
        raise UserError(
            "%s: only %d usable points of %d rows (need at least %d after dropping rail-clipped and non-numeric rows)"
            % (source, n, n_input, MIN_POINTS)
        )
    span = float(x[-1] - x[0])
    if span <= 0 or float(np.ptp(y)) <= 0:
        raise UserError("%s: raw or reference never changes, so there is no curve to fit" % source)
    if fs is not None and span < MIN_COVERAGE * fs:
        raise UserError(
            "%s: raw covers only %s of its full scale %s (%.0f %%); sweep the whole stroke (at least %.0f %%)"
            % (source, _fmt(span), _fmt(fs), 100 * span / fs, 100 * MIN_COVERAGE)
        )
    gap = float(np.max(np.diff(x)))
    if gap > MAX_GAP * span:
        at = int(np.argmax(np.diff(x)))
        raise UserError(
            "%s: no readings between raw %s and %s (%.0f %% of the span); sweep more slowly or add points there"
            % (source, _fmt(x[at]), _fmt(x[at + 1]), 100 * gap / span)
        )


def _fmt(v):
    return "%d" % v if float(v).is_integer() else "%.4g" % v


__all__ = ["Sweep", "load_sweep", "sweep_from_arrays", "MIN_POINTS"]
