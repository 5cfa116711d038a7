"""F0(d) of a preloaded spring pair as a cubic spline with one kink on each side.

While the preload keeps both springs of the pair in contact, the net force is smooth in the
deformation. Where one spring has lost its preload (at some force on each side, 10-30 N for the
5-15 N preloads the robustness bench draws) it lifts off, and from there only the other spring
acts: the stiffness drops, all at one deformation. A polynomial of order <= 5 cannot follow that
kink, and a free-knot table (host/fitting/force.py) places its few knots by the noise of the
points around it: replayed over fresh actuators (bench/bench_force_fit_replay.py) it was 30-60 mN
off at 2-4 N, where 2 % is 40-80 mN, and on one actuator 0.5 N off at 12 N, the kink put in the
wrong gap between two levels.

So the spline keeps the kink's physics and leaves the rest generic:
- a cubic in d, with (optionally, `split`) its second and third derivatives free to change at
  d = 0: each side of the range loads a different spring more, and the points of the two sides
  come from two different gauge set-ups;
- on each side, optionally, a slope change max(0, d - r) (or max(0, r - d)) at a kink r found by a
  fine search (KINK_STEP_MM): between levels the slopes on either side of the kink are pinned by
  the levels beyond it, so the least squares places it inside a gap, where a knot search cannot;
  at least MIN_BEYOND points must lie beyond it.
The block's friction h is one more column, as in the polynomial fit. The firmware evaluates F0 as
a table (firmware/pwl_fixed.py): `tabulate` samples the spline every TABLE_STEP_MM and at its
kinks, linear between them (a cubic's curvature of up to 3 N/mm^2 leaves under 1 mN between
samples), and d(F0) is that table's exact inverse.

Whether the spline replaces the polynomial or the free-knot table is decided in force.py, by
cross-validation.
"""

from dataclasses import dataclass

import numpy as np

from host.fitting.cross_validation import cv_rms as _cv_rms

KINK_STEP_MM = 0.01  # the kink search's grid
KINK_NEAR_ZERO_MM = 0.1  # no kink closer to 0 than this: the preload holds at the smallest forces
MIN_BEYOND = 4  # points beyond a kink (a level or two), to pin the slope after it
TABLE_STEP_MM = 0.05


@dataclass
class SpringSpline:
    kink_low_mm: float  # or None: no kink on the negative side
    kink_high_mm: float  # or None
    split: bool  # the curvature changes at d = 0
    coeffs: np.ndarray  # of the columns, in `columns`' order
    friction_n: float

    def f0(self, d):
        """F0 at deformations d (mm), N."""
        return columns(np.asarray(d, dtype=float), self.kink_low_mm, self.kink_high_mm, self.split) @ self.coeffs

    @property
    def kinks_mm(self):
        return [float(r) for r in (self.kink_low_mm, self.kink_high_mm) if r is not None]


def columns(d, kink_low, kink_high, split):
    """The spline's design matrix at deformations d (mm)."""
    cols = [np.vander(d, 4)]
    if split:
        p = np.maximum(d, 0.0)
        cols.append(np.column_stack([p * p, p * p * p]))
    if kink_high is not None:
        cols.append(np.maximum(d - kink_high, 0.0)[:, None])
    if kink_low is not None:
        cols.append(np.maximum(kink_low - d, 0.0)[:, None])
    return np.column_stack(cols)


def _solve(d, f, s, kink_low, kink_high, split, friction):
    """(coefficients, h, residual sum of squares) by linear least squares."""
    a = columns(d, kink_low, kink_high, split)
    if friction:
        a = np.column_stack([a, s])
    sol = np.linalg.lstsq(a, f, rcond=None)[0]
    rss = float(np.sum((f - a @ sol) ** 2))
    return (sol[:-1], float(sol[-1]), rss) if friction else (sol, 0.0, rss)


def _kink_grid(d, sign):
    """Candidate kinks on one side (None first: no kink), leaving MIN_BEYOND points beyond."""
    side = np.sort(sign * d[sign * d > 0])
    if len(side) < MIN_BEYOND + 2:
        return [None]
    return [None] + [sign * r for r in np.arange(KINK_NEAR_ZERO_MM, side[-MIN_BEYOND], KINK_STEP_MM)]


def fit_spline(d, f, s, split, friction=True):
    """The SpringSpline of least squares, its kinks found by coordinate search (each side's grid
    in turn, twice: the two sides barely interact)."""
    low_grid, high_grid = _kink_grid(d, -1), _kink_grid(d, 1)
    low = high = None
    for _ in range(2):
        high = min(high_grid, key=lambda r: _solve(d, f, s, low, r, split, friction)[2])
        low = min(low_grid, key=lambda r: _solve(d, f, s, r, high, split, friction)[2])
    coeffs, h, _ = _solve(d, f, s, low, high, split, friction)
    return SpringSpline(low, high, split, coeffs, h)


def cv_rms(d, f, s, split, friction=True):
    """Root mean square hold-out error of the spline (kinks searched again inside each fold)."""
    def fit(train):
        return fit_spline(d[train], f[train], s[train], split, friction)

    def residuals(model, test):
        return f[test] - model.f0(d[test]) - model.friction_n * s[test]

    return _cv_rms(len(d), fit, residuals)


def tabulate(spline, d_lo, d_hi):
    """(knots_d mm, knots_f N): the spline sampled over [d_lo, d_hi] every TABLE_STEP_MM, at 0 and
    at its kinks, each knot on a whole micrometre (the firmware's table holds um)."""
    xs = np.concatenate([np.arange(d_lo, d_hi, TABLE_STEP_MM), [d_lo, d_hi, 0.0], spline.kinks_mm])
    kx = np.unique(np.round(xs[(xs >= d_lo) & (xs <= d_hi)], 3))
    return kx, spline.f0(kx)
