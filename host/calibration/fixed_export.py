"""Export float calibrations to the firmware's integer forms, and prove each export is good.

Every export returns a `FixedExport` (a list of ints, the `k` the firmware functions take) that
also carries what was checked: `max_error` (largest |integer - float64| over every ADC code, or
over a dense grid of the input range for polynomials), `bound` (the limit it had to meet) and
`max_intermediate` (largest |value| any operation produced, measured by running the firmware
function itself on `TrackedInt`s, so there is no second copy of the arithmetic to drift apart).
An export that misses its bound, or whose intermediates exceed 2**30, raises ValueError with the
reason, so a bad curve never reaches a board.

Error bound for pot curves (bcm3, pwl, tables): half an ADC step of the curve's own span,
`0.5 * (max f - min f) / 2**adc_bits` um over codes 0..2**adc_bits - 1; for a 60 mm pot on a
12-bit ADC that is 60000 / 4096 / 2 = 7.32 um. Pass `max_error_um` to use another limit.
"""

import math

import numpy as np

from firmware import bcm_fixed, poly_fixed, pwl_fixed
from firmware.calibration import LIMIT, SEGMENT_LIMIT  # the firmware's own bounds: one definition
from host.calibration.tracked_int import track
from host.fitting.rational_bezier import evaluate as bcm_float  # the float64 reference curve

UM_PER_MM = 1000.0


class FixedExport(list):
    """The exported constants (a list of ints) plus the figures that justified them."""

    def __init__(self, values, kind, max_error, bound, max_intermediate, outputs=None):
        super().__init__(int(v) for v in values)
        self.kind = kind
        self.max_error = float(max_error)
        self.bound = float(bound)
        self.max_intermediate = int(max_intermediate)
        self.outputs = outputs  # what the firmware function gave at each checked input
        self.sampled = False  # a table of a curve sampled at evenly spaced codes, not of the fit's own knots

    def report(self):
        out = {
            "kind": self.kind,
            "max_error": self.max_error,
            "bound": self.bound,
            "max_intermediate": self.max_intermediate,
            "max_intermediate_log2": math.log2(max(self.max_intermediate, 1)),
        }
        if self.sampled:  # its knots are not the ones a section's coefficients list (consistency.py)
            out["sampled"] = True
        return out


def _input_shift(adc_bits, scaled_bits):
    if not 1 <= int(adc_bits) <= 16:
        raise ValueError("adc_bits must be 1..16, got %r" % (adc_bits,))
    return scaled_bits - int(adc_bits)


def _pot_bound(values_um, adc_bits, max_error_um):
    if max_error_um is not None:
        return float(max_error_um)
    return 0.5 * float(np.max(values_um) - np.min(values_um)) / 2**adc_bits


def _finish(kind, k, func, inputs, reference, bound, what, tracked=None):
    got = np.array([func(int(x), k) for x in inputs], dtype=float)
    err = float(np.max(np.abs(got - reference)))
    peak = track(func, inputs if tracked is None else tracked, k)
    if peak > LIMIT:
        raise ValueError("%s: an intermediate reaches %d > 2**30 (would overflow a 32-bit board)" % (what, peak))
    if not err <= bound:
        raise ValueError("%s: integer form is %.3g off float64, over the bound %.3g" % (what, err, bound))
    return FixedExport(k, kind, err, bound, peak, got)


# ---------------------------------------------------------------- BCM-3


def _mantissa(c):
    """(m, e) with c = m / 2**e and m in [2**18, 2**19] (the bcm3 float form of a weight ratio)."""
    f, x = math.frexp(c)  # c = f * 2**x, f in [0.5, 1)
    return round(f * 2**19), 19 - x


def export_bcm3(coefficients, adc_bits, max_error_um=None, unit_um=UM_PER_MM):
    """k for `firmware.bcm_fixed.bcm3` from a bcm coefficient dict (x in ADC codes, y in mm).

    `unit_um` is how many um one unit of the handles is (1000 for mm). Raises ValueError when
    the curve is not degree 3 or its integer form cannot meet the bound.
    """
    s = _input_shift(adc_bits, 29)
    w = [float(v) for v in coefficients["weights"]]
    p = [float(v) * unit_um for v in coefficients["handles"]]
    if len(w) != 4 or len(p) != 4:
        raise ValueError("bcm3 needs degree 3 (4 weights and handles), got %d: export a table instead" % (len(w) - 1))
    if not all(math.isfinite(v) and v > 0 for v in w):
        raise ValueError("bcm weights must be positive and finite")
    if not all(math.isfinite(v) for v in p):
        raise ValueError("bcm handles must be finite")
    lx = round(float(coefficients["lx"]) * 2**s)
    rx = round(float(coefficients["rx"]) * 2**s)
    if not (lx >= 0 and rx >= 2**19 and lx + rx <= 2**29):
        raise ValueError("lx/rx outside the %d-bit ADC range (lx=%r, rx=%r)" % (adc_bits, coefficients["lx"], coefficients["rx"]))
    # the weight ratios from each end, binomials included: c_i = C(3, i) w_i / w_0 and mirrored
    binomial = (1, 3, 3, 1)
    ratios = [_mantissa(binomial[i] * w[i] / w[0]) for i in (1, 2, 3)]
    ratios += [_mantissa(binomial[i] * w[3 - i] / w[3]) for i in (1, 2, 3)]
    if any(not -64 <= e <= 64 for _, e in ratios):
        raise ValueError("weight ratio %.3g too large for bcm3" % (max(w) / min(w)))
    h = 8  # finest handle unit 2**-h um whose spread and size still fit the layout
    while h > 0 and (round((max(p) - min(p)) * 2**h) + 1 > 2**21 or max(abs(v) for v in p) * 2**h >= 2**29):
        h -= 1
    handles = [round(v * 2**h) for v in p]
    if max(handles) - min(handles) > 2**21 or max(abs(v) for v in handles) >= 2**29:
        raise ValueError("handle spread %.0f um too large (limit 2**21 um)" % (max(p) - min(p)))
    k = [s, lx, rx, rx.bit_length() - 20, h, *handles, *(v for pair in ratios for v in pair)]
    why = bcm_fixed.invalid(k)
    if why:
        raise ValueError("bcm3: " + why)
    codes = np.arange(2**adc_bits)
    reference = bcm_float(coefficients, codes) * unit_um
    bound = _pot_bound(reference, adc_bits, max_error_um)
    return _finish("bcm3", k, bcm_fixed.bcm3, codes, reference, bound, "bcm3")


# ---------------------------------------------------------------- piecewise-linear tables



def _merge_close_knots(X, ys, same_um=1.0):
    """Knots that land on the same table input with values within `same_um` become one (a
    free-knot fit of 29-33 knots may put two at one code, or within 1/16 code, with the same value:
    seen at a pot's flat end and mid-curve). Refused, the fit fell back to a code-by-code table
    many times the size, past the 64 KiB a board reads. Knots at one input with different values
    (a step) are left for the checks to refuse."""
    outx, outy, count = [X[0]], [float(ys[0])], [1]
    for x, y in zip(X[1:], ys[1:]):
        if x == outx[-1] and abs(float(y) - outy[-1]) <= same_um:
            count[-1] += 1
            outy[-1] += (float(y) - outy[-1]) / count[-1]
        else:
            outx.append(x)
            outy.append(float(y))
            count.append(1)
    return outx, np.asarray(outy)


def export_pwl(knots_x, knots_y, adc_bits, max_error_um=None, unit_um=UM_PER_MM, reference=None):
    """k for `firmware.pwl_fixed.pwl` from knots (x in ADC codes increasing, y in mm).

    Segments too long for the 31-bit interpolation product are split (exactly on the line).
    `reference(codes) -> um` is what the table is checked against (default: the float
    interpolation of the knots themselves, clamped at the ends).
    """
    s = _input_shift(adc_bits, 16)
    xs = np.asarray(knots_x, dtype=float)
    ys = np.asarray(knots_y, dtype=float) * unit_um
    if xs.ndim != 1 or len(xs) < 2 or len(xs) != len(ys):
        raise ValueError("a table needs at least 2 knots with as many values as codes")
    if not (np.all(np.isfinite(xs)) and np.all(np.isfinite(ys))):
        raise ValueError("table knots must be finite")
    if np.any(np.diff(xs) < 0):
        raise ValueError("knot codes must be strictly increasing")
    X = [round(v * 2**s) for v in xs]
    X, merged = _merge_close_knots(X, ys)  # (knots at the same code among them)
    if any(b == a for a, b in zip(xs, xs[1:])) and len(X) == len(xs):
        raise ValueError("knot codes must be strictly increasing")
    if X[0] < 0 or X[-1] > 2**16 or any(b <= a for a, b in zip(X, X[1:])):
        raise ValueError("knot codes must be distinct within 1/%d code and inside the ADC range" % 2**s)
    Y = [round(v) for v in merged]
    if max(abs(v) for v in Y) >= 2**29:
        raise ValueError("table values exceed 2**29 um")
    # split segments whose interpolation product could leave 31 bits
    outx, outy = [X[0]], [Y[0]]
    for i in range(1, len(X)):
        x0, y0, x1, y1 = outx[-1], outy[-1], X[i], Y[i]
        pieces = 1
        while -(-(x1 - x0) // pieces) * abs(y1 - y0) > SEGMENT_LIMIT:
            pieces += 1
        for j in range(1, pieces):
            outx.append(x0 + (x1 - x0) * j // pieces)
            outy.append(round(y0 + (y1 - y0) * (outx[-1] - x0) / (x1 - x0)))
        outx.append(x1)
        outy.append(y1)
    k = [len(outx), s, *outx, *outy]
    codes = np.arange(2**adc_bits)
    ref = np.interp(codes, xs, ys) if reference is None else np.asarray(reference(codes), dtype=float)
    bound = _pot_bound(ref, adc_bits, max_error_um)
    return _finish("pwl", k, pwl_fixed.pwl, codes, ref, bound, "pwl table")


def export_force_table(knots_in, knots_out, in_range, in_scale=1000.0, out_scale=1000.0, offset=None, rising=True):
    """k for `firmware.pwl_fixed.pwl` evaluating a table section (F0(d): d mm -> N, its inverse:
    N -> mm, or Df(D1): mm -> mm) on integer inputs (um or mN) plus `offset` (default
    FORCE_PWL_OFFSET; a Df table takes DF_PWL_OFFSET), output in um or mN. `rising`: the values
    must rise too (a spring's force; a Df need not).

    The end segments are carried on straight to `in_range` (the cavity's +-2 mm, or the force
    range), where the firmware then clamps: a spring beyond the calibrated forces is taken to go
    on as it last did, not to stop. Checked at every integer input of that range."""
    xi = np.asarray(knots_in, dtype=float)
    yo = np.asarray(knots_out, dtype=float)
    if xi.ndim != 1 or len(xi) < 2 or len(xi) != len(yo) or not (np.all(np.isfinite(xi)) and np.all(np.isfinite(yo))):
        raise ValueError("a force table needs at least 2 finite knots with as many values")
    if np.any(np.diff(xi) <= 0) or rising and np.any(np.diff(yo) <= 0):
        raise ValueError("a force table must rise strictly (a spring's force grows with its deformation)")
    offset = pwl_fixed.FORCE_PWL_OFFSET if offset is None else int(offset)
    lo, hi = float(in_range[0]), float(in_range[1])
    if lo < xi[0]:
        yo = np.concatenate([[yo[0] - (yo[1] - yo[0]) / (xi[1] - xi[0]) * (xi[0] - lo)], yo])
        xi = np.concatenate([[lo], xi])
    if hi > xi[-1]:
        yo = np.concatenate([yo, [yo[-1] + (yo[-1] - yo[-2]) / (xi[-1] - xi[-2]) * (hi - xi[-1])]])
        xi = np.concatenate([xi, [hi]])
    X = [round(v * in_scale) + offset for v in xi]
    Y = [round(v * out_scale) for v in yo]
    if X[0] < 0 or X[-1] > 2**16 or any(b <= a for a, b in zip(X, X[1:])):
        raise ValueError("table inputs must be distinct and within %d..%d units" % (-offset, 2**16 - offset))
    if max(abs(v) for v in Y) >= 2**29 or any(
            (b - a) * abs(d - c) > SEGMENT_LIMIT for a, b, c, d in zip(X, X[1:], Y, Y[1:])):
        raise ValueError("force table values too large for 31 bits")
    k = [len(X), 0, *X, *Y]
    inputs = np.arange(X[0] - 8, X[-1] + 9)
    ref = np.interp(inputs, X, Y)  # the table's own line between its rounded knots
    return _finish("pwl", k, pwl_fixed.pwl, inputs, ref, 1.0, "force table")


def export_curve_table(f, adc_bits, n_points=None, max_error_um=None, unit_um=UM_PER_MM, x_range=None):
    """A pwl table that samples the monotone curve `f` (a FitResult or any codes -> mm callable).

    Knots are evenly spaced over `x_range` (default: f.x_range, else the whole ADC range) and the
    table is checked against f at every code (f clamped to x_range, as the table is). With
    n_points None, the smallest of 17, 33, 65, ... knots that meets the bound is used.
    """
    if x_range is None:
        x_range = getattr(f, "x_range", None) or (0, 2**adc_bits - 1)
    lo, hi = float(x_range[0]), float(x_range[1])
    lo, hi = max(lo, 0.0), min(hi, float(2**adc_bits - 1))
    if not hi > lo:
        raise ValueError("empty input range %r" % (x_range,))

    def reference(codes):
        return np.asarray(f(np.clip(codes.astype(float), lo, hi)), dtype=float) * unit_um

    tries = [n_points] if n_points else [2**m + 1 for m in range(4, adc_bits + 1)]
    err = None
    for n in tries:
        n = int(min(n, math.floor(hi - lo) + 1)) if hi - lo >= 1 else 2
        kx = np.linspace(lo, hi, max(n, 2))
        ky = np.asarray(f(kx), dtype=float)
        d = np.diff(ky)
        if not (np.all(d >= 0) or np.all(d <= 0)):
            raise ValueError("curve is not monotone over its range: a table of it cannot be trusted")
        try:
            table = export_pwl(kx, ky, adc_bits, max_error_um, unit_um, reference=reference)
        except ValueError as e:
            err = e
            continue
        table.sampled = True
        return table
    raise ValueError("no table of up to %d points meets the bound: %s" % (tries[-1], err))


def _rising(fixed):
    """`fixed` if its positions never fall as the code rises (the firmware refuses such a curve
    at boot, see firmware/measurement.py), else ValueError saying where: a calibration the board
    would refuse is never written."""
    steps = np.diff(fixed.outputs)
    if steps.size and np.min(steps) < 0:
        code = int(np.argmin(steps)) + 1
        raise ValueError("the integer curve falls at code %d (%d um after %d): positions must grow with the code"
                         % (code, fixed.outputs[code], fixed.outputs[code - 1]))
    return fixed


def export_pot(fit, adc_bits, max_error_um=None, unit_um=UM_PER_MM, rising=False):
    """(kind, FixedExport) for a pot FitResult: bcm3 when possible, else the best table. With
    `rising`, only an integer curve whose positions never fall is returned (what a board accepts)."""
    check = _rising if rising else (lambda fixed: fixed)
    c = fit.coefficients
    if fit.model == "bcm" and len(c.get("weights", ())) == 4:
        try:
            return "bcm3", check(export_bcm3(c, adc_bits, max_error_um, unit_um))
        except ValueError:
            pass
    if fit.model in ("lut", "pwl"):
        try:
            return "pwl", check(export_pwl(c["knots_x"], c["knots_y"], adc_bits, max_error_um, unit_um))
        except ValueError:
            pass
    return "pwl", check(export_curve_table(fit, adc_bits, max_error_um=max_error_um, unit_um=unit_um))


# ---------------------------------------------------------------- polynomials


def _poly_words(q, n, xc, xlo, xhi, lim):
    """The poly_fixed layout of q(u) (lowest first, degree n) with accumulator exponents at most `lim`."""
    e = [0] * (n + 1)
    e[n] = lim[n]
    for j in range(n - 1, -1, -1):
        e[j] = min(lim[j], e[j + 1] - 8)
    e[0] = min(e[0], 30)  # E0 in 0..30 (a zero polynomial has no limit of its own)
    for j in range(n):
        e[j + 1] = min(e[j + 1], e[j] + 30)  # SH_j in 8..30
    if e[0] < 0:
        raise ValueError("polynomial output beyond 2**29 output units over the input range")
    k = [n, xc, xlo, xhi, e[0], round(q[n] * 2.0 ** e[n])]
    for j in range(n - 1, -1, -1):
        k += [e[j + 1] - e[j], round(q[j] * 2.0 ** e[j])]
    return k


def export_poly(coeffs_high_first, x_min, x_max, in_scale, out_scale, max_error=None):
    """k for `firmware.poly_fixed.poly` evaluating out_scale * P(x / in_scale) on integer x.

    P has coefficients `coeffs_high_first` (numpy.polyval order) in its natural units, e.g.
    Df_hat in mm of D1 in mm: in_scale = out_scale = 1000 gives um -> um. x_min, x_max are the
    input range in P's natural units (mm here); the firmware clamps to it. The result is checked
    on every integer input (or a 200,001-point grid of a wider range); `max_error` defaults to
    max(1, 2**-13 * max |output|) output units.
    """
    a = np.asarray(coeffs_high_first, dtype=float)
    if a.ndim != 1 or len(a) < 1 or not np.all(np.isfinite(a)):
        raise ValueError("polynomial coefficients must be a non-empty list of finite numbers")
    n = len(a) - 1
    xlo, xhi = math.ceil(x_min * in_scale), math.floor(x_max * in_scale)
    if not xhi >= xlo or max(abs(xlo), abs(xhi)) >= 2**29:
        raise ValueError("input range %r..%r is empty or beyond 2**29 units" % (x_min, x_max))
    xc = (xlo + xhi) // 2
    hw = max(xc - xlo, xhi - xc, 1)
    # coefficients of q(u) = out_scale * P((u + xc) / in_scale), lowest first
    shift = np.polynomial.Polynomial([xc / in_scale, 1.0 / in_scale])
    q = (np.polynomial.Polynomial(a[::-1]) * out_scale)(shift).coef
    q = np.concatenate([q, np.zeros(n + 1 - len(q))])
    while n > 0 and q[n] == 0:  # leading zeros would only cost exponent range
        n -= 1
    # Exponents: |R_j| = |r_j(u)| 2**E_j <= 2**29 and, for j >= 1, |R_j| * max(256, |uh|) <= 2**29
    # (the firmware takes R_j * u in halves, u = uh * 2**8 + ul), where
    # r_j(u) = sum_(i>=j) q_i u^(i-j) is the Horner accumulator. Up to 200,001 integer inputs
    # the maxima are taken over every input the firmware can see (it clamps to the range);
    # beyond, the bound sum |q_i| hw^(i-j) is used. The factor 2 to 2**30 absorbs rounding.
    inputs = np.arange(xlo, xhi + 1) if xhi - xlo <= 200000 else None
    lim = []
    for j in range(n + 1):
        if inputs is not None:
            u = (inputs - xc).astype(float)
            r = np.zeros_like(u)
            for i in range(n, j - 1, -1):
                r = r * u + q[i]
            mj = float(np.max(np.abs(r)))
        else:
            mj = sum(abs(q[i]) * float(hw) ** (i - j) for i in range(j, n + 1))
        mj *= max(256, (hw >> 8) + 1) if j >= 1 else 1
        lj = 200 if mj == 0 else min(200, math.floor(29 - math.log2(mj)))
        if mj * 2.0**lj >= 2**29:  # keep |R_j| < 2**29 strictly (the firmware's sign fix)
            lj -= 1
        lim.append(lj)
    # the board accepts a polynomial only when firmware.poly_fixed.overflow proves its 31-bit
    # bounds from the words; that proof is a little looser than the maxima above, so when it
    # fails every exponent gives up one bit and the proof is tried again
    for backoff in range(8):
        k = _poly_words(q, n, xc, xlo, xhi, [lj - backoff for lj in lim])
        why = poly_fixed.invalid(k)
        if why is None:
            break
    else:
        raise ValueError("polynomial cannot be proved to stay within 31 bits: %s" % why)
    if inputs is None:
        inputs = np.unique(np.linspace(xlo, xhi, 200001).round())
    reference = np.polyval(a, inputs / in_scale) * out_scale
    bound = max(1.0, 2.0**-13 * float(np.max(np.abs(reference)))) if max_error is None else float(max_error)
    # the board relies on the proof above; instrumenting 4,001 inputs (ends included) checks it again
    tracked = inputs if len(inputs) <= 4001 else np.unique(np.linspace(xlo, xhi, 4001).round())
    return _finish("poly", k, poly_fixed.poly, inputs, reference, bound, "polynomial", tracked)
