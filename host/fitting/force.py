"""The force model (the paper's section 4): F0(d) from spring deformation, its inverse d(F0), and
the output block's friction.

The gauge reads the spring force minus the block's Coulomb friction h in the direction the block
slid: F_gauge = F0(d) + h * s, with s = +1 after the force fell (the block slid toward 0 mm) and
-1 after it rose. Fitted without it, loading and unloading disagree by ~2h and the fit carries
+-h of error (docs/paper-experiments.md measures both). F0 and h are fitted together by linear
least squares (h is one more column); d(F0) is fitted to the spring force F_gauge - h * s. The
firmware turns h into a play operator on F0(d) (firmware/measurement.py). Orders: `auto` picks
the lowest within 5 % of the best cross-validated error (host/fitting/cross_validation.py); an
integer fixes it (the paper's quadratics: 2).

A spring pair whose preload ends inside the force range halves its stiffness at one deformation,
a kink no polynomial of order <= 5 follows: when cross-validation says a free-knot table
(host/fitting/piecewise_linear.py) predicts clearly better, F0 is that table, and d(F0) its exact
inverse. With the order left to cross-validation, a cubic spline with a kink on each side
(host/fitting/spring_spline.py) then replaces the table when it predicts about as well (within
NEAR_BEST), or the polynomial when it predicts clearly better (SPLINE_GAIN); the firmware gets it
as a dense table.

A point taken just after the force turned (the last loading level, then the first unloading
ones) sits at the band's edge only if the spring has since moved 2h: until then the block has
not slid, and the gauge holds whatever friction the turn left (seed 1004 of docs/robustness.md:
one 1.5 N unloading level under a 2 x 0.96 N band, friction -0.57 N where the model says
-0.92). So does a round's first level, where the block met the fibre after sliding free. Given
the points' order (`loading`), `fit_force` leaves such points out and fits again.
"""

from dataclasses import dataclass, field

import numpy as np

from host.errors import UserError
from host.fitting.cross_validation import cv_rms as _cv_rms
from host.fitting.cross_validation import NEAR_BEST, lowest_near_best
from host.fitting.piecewise_linear import fit_pwl, hat_matrix
from host.fitting.spring_spline import cv_rms as spline_cv_rms
from host.fitting.spring_spline import fit_spline, tabulate

MAX_ORDER = 5


@dataclass
class ForceFit:
    coeffs_f: np.ndarray  # F0(d), N of mm, numpy.polyval order
    coeffs_d: np.ndarray  # d(F0), mm of N (of the spring force)
    friction_n: float  # h; 0 when fitted without friction
    rms_n: float  # of F_gauge - (F0(d) + h s)
    max_n: float
    rms_d_mm: float  # of d - d(F_gauge - h s)
    order_f: int
    order_d: int
    scores: dict = field(default_factory=dict)  # order -> cross-validated rms (N)
    kind: str = "poly"  # or "pwl": F0 is the table (knots_d, knots_f), d(F0) its exact inverse
    knots_d: np.ndarray = None
    knots_f: np.ndarray = None
    table_scores: dict = field(default_factory=dict)  # knots -> cross-validated rms (N)
    spline_scores: dict = field(default_factory=dict)  # "cubic"/"split cubic" -> cross-validated rms (N)
    kinks_mm: list = None  # when F0 is a spring spline's table (host/fitting/spring_spline.py): its kinks
    left_out: np.ndarray = None  # points inside the friction band after a turn (mask), not fitted

    def f0(self, d):
        """F0 at deformations d (mm), N; a table goes on straight past its end knots, as its export does."""
        d = np.asarray(d, dtype=float)
        return table_value(d, self.knots_d, self.knots_f) if self.kind == "pwl" else np.polyval(self.coeffs_f, d)


def table_value(x, kx, ky):
    """A table at x, going on straight past its end knots (as host.calibration.fixed_export carries it on)."""
    x = np.asarray(x, dtype=float)
    lo = ky[0] + (x - kx[0]) * (ky[1] - ky[0]) / (kx[1] - kx[0])
    hi = ky[-1] + (x - kx[-1]) * (ky[-1] - ky[-2]) / (kx[-1] - kx[-2])
    return np.where(x < kx[0], lo, np.where(x > kx[-1], hi, np.interp(x, kx, ky)))


def _design(d, s, order, friction):
    a = np.vander(d, order + 1)
    return np.column_stack([a, s]) if friction else a


def _solve(d, f, s, order, friction):
    sol = np.linalg.lstsq(_design(d, s, order, friction), f, rcond=None)[0]
    return (sol[:-1], float(sol[-1])) if friction else (sol, 0.0)


def cv_rms(d, f, s, order, friction):
    """Root mean square hold-out error of the F0 fit."""
    def residuals(model, test):
        c, h = model
        return f[test] - np.polyval(c, d[test]) - h * s[test]

    return _cv_rms(len(d), lambda train: _solve(d[train], f[train], s[train], order, friction), residuals)


def _solve_table(d, f, s, kx, friction):
    """Knot values (and h) by least squares. A knot span with no points (a cross-validation fold
    can leave one) would get any value; a faint penalty on the change of slope at each interior
    knot puts such knots on the line through their neighbours and leaves the rest to the data."""
    a = hat_matrix(d, kx)
    if friction:
        a = np.column_stack([a, s])
    k = len(kx)
    if k > 2:
        h = np.maximum(np.diff(kx), 1e-9)
        rows = np.zeros((k - 2, a.shape[1]))
        for i in range(k - 2):
            rows[i, i], rows[i, i + 1], rows[i, i + 2] = 1 / h[i], -1 / h[i] - 1 / h[i + 1], 1 / h[i + 1]
        weight = 1e-3 * np.sqrt(len(d)) / np.max(np.abs(rows))
        a = np.vstack([a, weight * rows])
        f = np.concatenate([f, np.zeros(k - 2)])
    sol = np.linalg.lstsq(a, f, rcond=None)[0]
    return (sol[:-1], float(sol[-1])) if friction else (sol, 0.0)


def table_knots(d, spring, k):
    """Knot positions of a k-knot free-knot piecewise-linear F0 (host.fitting.piecewise_linear)."""
    order = np.argsort(d, kind="stable")
    return np.asarray(fit_pwl(d[order], spring[order], k, monotone="off").coefficients["knots_x"])


def cv_rms_table(d, f, s, k, friction, h0, full_knots):
    """Root mean square hold-out error of a k-knot table F0 (on the polynomial's folds; the knots
    are chosen again inside each fold, on the spring force with friction h0, so the score is not
    flattered). A fold whose own knots fold the table (two knots in a gap the fold left at an
    end: a held-out end point then lands 20 N off), or that is not spring_like, takes the full
    data's knots."""
    def fit(train):
        kx = table_knots(d[train], f[train] - h0 * s[train], k)
        v, h = _solve_table(d[train], f[train], s[train], kx, friction)
        if np.any(np.diff(kx) <= 0) or not spring_like(kx, v):
            kx = full_knots
            v, h = _solve_table(d[train], f[train], s[train], kx, friction)
        return kx, v, h

    def residuals(model, test):
        kx, v, h = model
        return f[test] - table_value(d[test], kx, v) - h * s[test]

    return _cv_rms(len(d), fit, residuals)


def inside_band(spring_n, loading, h):
    """Mask of the points, in the order taken, whose block may rest anywhere inside its friction
    band, not at the edge (-+h) the model gives it:
    - after a turn of the force (loading, then unloading), while the spring force is still within
      2h of its value at the turn: the block has not slid since;
    - a round's first level (a loading point after unloading ones, or the very first), and those
      after it within 2h of it. The force step starts each round from a slack fibre (it moves the
      block there to tare the gauge): the block slides free, meets the fibre at speed and comes
      to rest wherever the fibre's rebound leaves it. Replayed from the fresh runs of stops 45 and
      46, those first levels sat 0.2-0.55 N off the edge on most actuators, and the fit bent F0
      toward them: 30-70 mN too steep at 2-4 N (docs/robustness.md, "Stop 47").
    """
    out = np.zeros(len(spring_n), dtype=bool)
    turn = None
    for i in range(len(spring_n)):
        if loading[i] and (i == 0 or not loading[i - 1]):
            out[i] = True
            turn = spring_n[i]
            continue
        if i > 0 and loading[i] != loading[i - 1]:
            turn = spring_n[i - 1]
        if turn is not None:
            if abs(spring_n[i] - turn) < 2.0 * h:
                out[i] = True
            else:
                turn = None  # slid: every later point of this run of levels is on the edge
    return out


def fit_force(d_mm, force_n, s, order="auto", friction=True, tables=True, loading=None, spline=True):
    """F_gauge = F0(d) + h s and d(F0 = F_gauge - h s) by least squares: a ForceFit (`tables`:
    a free-knot table or spring spline may replace the polynomial; `spline`: the spline may). With
    `loading` (the points in the order taken, True while the force rose), points inside the
    friction band after a turn (inside_band, on the fitted F0 and h) are left out and the fit
    made again, until the set stops changing; `left_out` says which."""
    d, f, s = (np.asarray(v, dtype=float) for v in (d_mm, force_n, s))
    fit = _fit_force(d, f, s, order, friction, tables, spline)
    fit.left_out = np.zeros(len(d), dtype=bool)
    if loading is None or not friction:
        return fit
    loading = np.asarray(loading, dtype=bool)
    for _ in range(4):
        out = inside_band(fit.f0(d), loading, fit.friction_n)
        if np.array_equal(out, fit.left_out) or np.count_nonzero(~out) < 6:
            break
        keep = ~out
        fit = _fit_force(d[keep], f[keep], s[keep], order, friction, tables, spline)
        fit.left_out = out
    return fit


def _fit_force(d_mm, force_n, s, order, friction, tables, spline):
    d = np.asarray(d_mm, dtype=float)
    f = np.asarray(force_n, dtype=float)
    s = np.asarray(s, dtype=float)
    top = min(MAX_ORDER, len(d) // 3)
    if top < 1:
        raise UserError("force: too few points with the fibre taut (%d)" % len(d))
    scores = {n: cv_rms(d, f, s, n, friction) for n in range(1, top + 1)}
    chosen = order == "auto"  # a fixed order asked for that polynomial (the paper's method: 2): no spline then
    if chosen:
        order = lowest_near_best(scores)
    order = int(order)
    cf, h = _solve(d, f, s, order, friction)
    if h < 0:  # friction cannot push the way the block slides: a fit artefact, drop the term
        cf, h = _solve(d, f, s, order, False)
    spring = f - h * s
    cd = np.polyfit(spring, d, order)
    resid = f - np.polyval(cf, d) - h * s
    rd = d - np.polyval(cd, spring)
    fit = ForceFit(cf, cd, h, float(np.sqrt(np.mean(resid**2))), float(np.max(np.abs(resid))),
                   float(np.sqrt(np.mean(rd**2))), order, order, scores)
    if tables and len(d) >= 12:
        _try_table(fit, d, f, s, friction, min(scores.values()))
    if tables and spline and chosen and len(d) >= SPLINE_MIN_POINTS:
        _try_spline(fit, d, f, s, friction, min(fit.table_scores.values()) if fit.kind == "pwl" else scores[order])
    return fit


SLOPE_SPREAD = 5.0  # a table's steepest segment may be at most this many times its flattest
SLOPE_DIP = 0.5  # ... and no segment may be softer than this fraction of both its neighbours


def spring_like(kx, values):
    """Whether a table can be a spring pair's F0: it rises, its stiffness stays within
    SLOPE_SPREAD of itself, and it never dips: no segment is softer than SLOPE_DIP of both its
    neighbours. A pair's stiffness halves where one spring lifts off its preload, and stays so,
    and hardening adds under 2x over the cavity. A table much flatter than that somewhere has put
    knots in a gap between the points (seen on a 46 N motor's 3.6 N levels: a segment of
    0.09 N/mm next to one of 44, 25 % off at 5 N), or two knots on one level's loading and
    unloading points (a segment of 3.8 N/mm between two of 16-19, 58 um long: 0.4 N off at
    10 N), which cross-validation need not notice."""
    slopes = np.diff(values) / np.diff(kx)
    if not (np.all(slopes > 0) and np.max(slopes) <= SLOPE_SPREAD * np.min(slopes)):
        return False
    inner = slopes[1:-1]
    return bool(np.all(inner >= SLOPE_DIP * np.minimum(slopes[:-2], slopes[2:])))


KNOT_SPACING = 0.75  # a table's knots stay at least this fraction of the levels' spacing apart
LEVEL_TOL_MM = 0.02  # deformations closer than this are one level


def level_spacing(d):
    """The typical spacing of the points' deformation levels, mm. The force step's open-loop
    levels set the spring force, so every round (loading or unloading) lands on the same few
    deformations: F0 is only measured there."""
    gaps = np.diff(np.sort(np.asarray(d, dtype=float)))
    gaps = gaps[gaps > LEVEL_TOL_MM]
    return float(np.median(gaps)) if len(gaps) else 0.0


def knots_spaced(kx, d):
    """Whether no two knots share one gap between levels: two knots between the same two levels
    leave the table's shape there to the noise (seed 1006 of docs/robustness.md, 3.6 N levels
    0.22 mm apart: knots 58 um apart, the table 0.6 N high at 10 N)."""
    return bool(np.min(np.diff(kx)) >= KNOT_SPACING * level_spacing(d))


TABLE_KNOTS = range(3, 9)
TABLE_GAIN = 0.8  # a table replaces the polynomial when its hold-out error is at most this fraction


def _try_table(fit, d, f, s, friction, poly_cv):
    """Replace the polynomial F0 by a free-knot table when cross-validation says it predicts
    clearly better (rms 0.2-0.3 N for a polynomial across a spring's lift-off, where the table
    leaves the gauge's noise). The table must rise, so its inverse is a table too."""
    spring0 = f - fit.friction_n * s
    tables = {}
    for k in TABLE_KNOTS:
        if len(d) < 3 * k:
            break
        kx = table_knots(d, spring0, k)
        values, h = _solve_table(d, f, s, kx, friction)
        if h < 0:
            values, h = _solve_table(d, f, s, kx, False)
        if spring_like(kx, values) and knots_spaced(kx, d):  # a knot span without data can fold or flatten the table
            tables[k] = (kx, values, h)
    fit.table_scores = {k: cv_rms_table(d, f, s, k, friction, fit.friction_n, tables[k][0]) for k in tables}
    if not fit.table_scores:
        return
    k = lowest_near_best(fit.table_scores, min(fit.table_scores))
    if min(fit.table_scores.values()) > TABLE_GAIN * poly_cv:
        return
    kx, values, h = tables[k]
    resid = f - np.interp(d, kx, values) - h * s
    spring = f - h * s
    rd = d - np.interp(spring, values, kx)
    fit.kind, fit.knots_d, fit.knots_f, fit.friction_n = "pwl", kx, values, h
    fit.rms_n, fit.max_n = float(np.sqrt(np.mean(resid**2))), float(np.max(np.abs(resid)))
    fit.rms_d_mm = float(np.sqrt(np.mean(rd**2)))


SPLINE_MIN_POINTS = 20  # a spline has up to 8 coefficients and 2 kinks (and h): cross-validation needs several points for each
SPLINE_SHAPES = {"cubic": False, "split cubic": True}
SPLINE_GAIN = 0.9  # the spline replaces a polynomial when its hold-out error is at most this fraction of the polynomial's


def _try_spline(fit, d, f, s, friction, chosen_cv):
    """Replace F0 by a spring spline's table (host/fitting/spring_spline.py) when it predicts
    clearly better than the polynomial chosen so far (cross-validated rms at most SPLINE_GAIN of
    `chosen_cv`: on a spring with no lift-off in range a spline with a kink put anywhere matches
    about as well as a polynomial, and then the paper's polynomial stays), or, when a free-knot
    table was chosen (a kink is there), about as well as the table (within NEAR_BEST, the margin
    by which the simpler of two models is taken): the spline has fewer numbers than a table of
    seven or more knots and puts its kinks where the levels on either side say, where the table
    puts its knots where the noise says; replayed over fresh actuators, the spline was the closer
    at 2-4 N (docs/robustness.md, "Stop 48")."""
    fit.spline_scores = {name: spline_cv_rms(d, f, s, split, friction) for name, split in SPLINE_SHAPES.items()}
    name = min(fit.spline_scores, key=fit.spline_scores.get)
    if fit.spline_scores[name] > (NEAR_BEST if fit.kind == "pwl" else SPLINE_GAIN) * chosen_cv:
        return
    spline = fit_spline(d, f, s, SPLINE_SHAPES[name], friction)
    if spline.friction_n < 0:  # as for the polynomial: friction cannot push the way the block slides
        spline = fit_spline(d, f, s, SPLINE_SHAPES[name], False)
    kx, values = tabulate(spline, float(np.min(d)), float(np.max(d)))
    if not spring_like(kx, values):
        return
    h = spline.friction_n
    resid = f - np.interp(d, kx, values) - h * s
    spring = f - h * s
    fit.kind, fit.knots_d, fit.knots_f, fit.friction_n, fit.kinks_mm = "pwl", kx, values, h, spline.kinks_mm
    fit.rms_n, fit.max_n = float(np.sqrt(np.mean(resid**2))), float(np.max(np.abs(resid)))
    fit.rms_d_mm = float(np.sqrt(np.mean((d - np.interp(spring, values, kx)) ** 2)))


def hysteresis_n(d, f, loading, order):
    """Largest gap between loading and unloading fits of F0(d) over their common range (N)."""
    if np.count_nonzero(loading) <= order or np.count_nonzero(~loading) <= order:
        return float("nan")
    cl = np.polyfit(d[loading], f[loading], order)
    cu = np.polyfit(d[~loading], f[~loading], order)
    lo = max(d[loading].min(), d[~loading].min())
    hi = min(d[loading].max(), d[~loading].max())
    grid = np.linspace(lo, hi, 200)
    return float(np.max(np.abs(np.polyval(cl, grid) - np.polyval(cu, grid))))
