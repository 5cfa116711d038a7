"""The closed-loop correction of F0(d): the spring-force error the force loop's holds measure.

The force step fits F0(d) to open-loop duty levels, a few deformations per side, and a
polynomial or a table of few knots carries tens of mN of error between them (up to 0.1-0.25 N
on some of the simulated actuators of docs/robustness.md, 1-2 % of a 5 N step on a 2 % target).
The friction trim's holds (host/guided/friction_trim.py) compare the running estimate with the
gauge at a few forces on each side. Once h is trimmed, what is left of estimate - gauge is the
same while loading and unloading: that is F0's error at that force, `c(F)` (force magnitudes).

The corrected F0 is a table that follows F0 - c within TABLE_TOL_N over the stretch where F0
rises, c taken on each side as a line from 0 at zero force through the holds' errors and flat
beyond the last one. Its inverse is the same knots swapped, so F0 and d(F0) still agree. An
error larger than CORRECTION_LIMIT says a hold went wrong (a slipping fibre, a drifting gauge),
not a fit: the correction is then refused and F0 kept.
"""

from dataclasses import dataclass, field

import numpy as np

from host.fitting.force import table_value

TABLE_TOL_N = 0.002  # the table follows F0 - c this closely
# A corrected table has at most this many knots: with its inverse each costs about 100 bytes of
# the calibration file, which the board reads only up to firmware.calibration.MAX_BYTES. Within
# TABLE_TOL_N, the force step's own tables and the corrected ones of the robustness runs need
# 33-70; an F0 polynomial fitted to few levels can bend enough to need hundreds (a CI run's
# calibration grew to 68 KB and the board refused it). Capped, such a table strays a few mN from
# F0 - c, far inside a 2 % force target; beyond MAX_STRAY_N the correction is refused.
MAX_TABLE_KNOTS = 128
MAX_STRAY_N = 0.01
SPAN_OF_RANGE = 0.9
CORRECTION_LIMIT = (0.1, 0.3)  # an error beyond this fraction of its force and this many N is not trusted


@dataclass
class F0Correction:
    errors: dict = field(default_factory=dict)  # side sign (+1, -1) -> [(force magnitude N, error N)], ascending
    why: str = ""  # why F0 is kept as it is, else empty

    def at(self, force_n):
        """The error c of the estimate at spring forces `force_n` (signed, N), in the forces' own sign."""
        force_n = np.asarray(force_n, dtype=float)
        out = np.zeros_like(force_n)
        for sign, rows in self.errors.items():
            if not rows:
                continue
            m = np.array([0.0] + [r[0] for r in rows])
            c = np.array([0.0] + [r[1] for r in rows])
            on_side = np.sign(force_n) == sign
            out[on_side] = sign * np.interp(sign * force_n[on_side], m, c)
        return out


def f0_function(section):
    """F0 (N of mm) of a calibration's `force` section, poly or table, as the firmware evaluates it
    within the deformations calibrated (a table goes on straight past its end knots)."""
    if section["kind"] == "pwl":
        kx, ky = np.asarray(section["knots_in"]), np.asarray(section["knots_out"])
        return lambda d: table_value(np.asarray(d, dtype=float), kx, ky)
    coeffs = np.asarray(section["coefficients"])
    return lambda d: np.polyval(coeffs, np.asarray(d, dtype=float))


def common_errors(rows, friction_change_n):
    """F0's error on one side from its holds, `rows` (target magnitude N, estimate magnitude N,
    gauge magnitude N, loading: bool), taut only, once h has moved by `friction_change_n` (a larger
    h lowers a loading estimate and raises an unloading one): [(magnitude, mean error N)]."""
    by_target = {}
    for target, estimate, gauge, loading in rows:
        error = estimate - gauge + (-friction_change_n if loading else friction_change_n)
        by_target.setdefault(round(target, 3), []).append(error)
    return [(m, float(np.mean(v))) for m, v in sorted(by_target.items())]


def f0_correction(errors):
    """The F0Correction of the errors per side ({sign: common_errors(...)}), or why it is refused."""
    for sign, rows in errors.items():
        for m, c in rows:
            if abs(c) > max(CORRECTION_LIMIT[0] * m, CORRECTION_LIMIT[1]):
                return F0Correction(errors, "F0 would move by %+.0f mN at %.1f N, more than %d %% of it and %.0f mN" % (
                    1000 * c, sign * m, 100 * CORRECTION_LIMIT[0], 1000 * CORRECTION_LIMIT[1]))
    if not any(errors.values()):
        return F0Correction(errors, "no hold with a taut fibre")
    return F0Correction(errors)


def table_knots(g, d_lo, d_hi, keep=()):
    """Deformation knots (mm) over d_lo..d_hi, with `keep` (kinks: an old table's knots, where the
    correction turns): a knot is added where the line between them strays most from g until it
    stays within TABLE_TOL_N everywhere (few knots where F0 is straight, more where it bends), or
    MAX_TABLE_KNOTS are placed. ValueError when the line then still strays more than MAX_STRAY_N."""
    dense = np.linspace(d_lo, d_hi, 2001)
    want = g(dense)
    kx = np.union1d([d_lo, d_hi], [k for k in keep if d_lo < k < d_hi])
    while True:
        miss = np.abs(np.interp(dense, kx, g(kx)) - want)
        worst = int(np.argmax(miss))
        if miss[worst] <= TABLE_TOL_N or len(kx) >= MAX_TABLE_KNOTS:
            break
        kx = np.union1d(kx, [dense[worst]])
    if miss[worst] > MAX_STRAY_N:
        raise ValueError("a table of %d knots still strays %.0f mN from F0 less the error: F0 bends too much to "
                         "tabulate" % (len(kx), 1000 * miss[worst]))
    return kx


def deformation_span(section, d_range_mm, f_range_n):
    """The deformations (mm) the table must cover: the stretch of d_range_mm around F0 = 0 over which
    the `section`'s F0 rises, cut where it leaves SPAN_OF_RANGE of f_range_n (the inverse's input
    range: the exporter carries the last segment on to its end, and a sliver of a segment would
    round to a step of 0 um). Beyond it
    the firmware's table goes on straight, as a table of the force step's own does. A side the
    gauge never loaded keeps its F0 this way (its c is 0); a polynomial that folds back near the
    cavity's end is cut at the fold. ValueError when F0 does not rise through 0."""
    f0 = f0_function(section)
    d = np.linspace(d_range_mm[0], d_range_mm[1], 4001)
    f = f0(d)
    f_range_n = [SPAN_OF_RANGE * v for v in f_range_n]
    zero = int(np.argmin(np.abs(f)))
    rising = np.diff(f) > 0
    if not (0 < zero < len(d) - 1 and f[zero - 1] < 0 < f[zero + 1]):
        raise ValueError("F0 does not rise through 0 N inside the cavity")
    lo = zero
    while lo > 0 and rising[lo - 1] and f[lo - 1] >= f_range_n[0]:
        lo -= 1
    hi = zero
    while hi < len(d) - 1 and rising[hi] and f[hi + 1] <= f_range_n[1]:
        hi += 1
    return float(d[lo]), float(d[hi])


def corrected_f0_table(section, d_span_mm, correction):
    """(knots_d mm, knots_f N) of the force `section`'s F0 less the correction, over the
    deformations `d_span_mm` (deformation_span, where F0 rises). Raises ValueError when the result
    would not rise (it cannot while |c| grows far slower than F0)."""
    f0 = f0_function(section)
    lo, hi = d_span_mm
    dense = np.linspace(lo, hi, 2001)
    turns = [float(np.interp(sign * m, f0(dense), dense)) for sign, rows in correction.errors.items() for m, _ in rows
             if f0(lo) < sign * m < f0(hi)]  # where c turns (f0 rises over the span)
    keep = list(section.get("knots_in", ())) if section["kind"] == "pwl" else []

    def corrected(d):
        f = f0(d)
        return f - correction.at(f)

    kx = table_knots(corrected, lo, hi, keep + turns)
    kf = corrected(kx)
    if np.any(np.diff(kf) <= 0):
        raise ValueError("the corrected F0 does not rise with the deformation")
    # the firmware's tables hold um and mN: a knot that would not rise after rounding goes
    kept = [0]
    for i in range(1, len(kx)):
        if round(kx[i] * 1000) > round(kx[kept[-1]] * 1000) and round(kf[i] * 1000) > round(kf[kept[-1]] * 1000):
            kept.append(i)
    if kept[-1] != len(kx) - 1:
        kept[-1] = len(kx) - 1  # the span's end stays; the knot before it was at least as far from the one before
    return kx[kept], kf[kept]
