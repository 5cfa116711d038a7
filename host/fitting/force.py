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
"""

from dataclasses import dataclass, field

import numpy as np

from host.errors import UserError
from host.fitting.cross_validation import cv_rms as _cv_rms
from host.fitting.cross_validation import lowest_near_best

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


def fit_force(d_mm, force_n, s, order="auto", friction=True):
    """F_gauge = F0(d) + h s and d(F0 = F_gauge - h s) by least squares: a ForceFit."""
    d = np.asarray(d_mm, dtype=float)
    f = np.asarray(force_n, dtype=float)
    s = np.asarray(s, dtype=float)
    top = min(MAX_ORDER, len(d) // 3)
    if top < 1:
        raise UserError("force: too few points with the fibre taut (%d)" % len(d))
    scores = {n: cv_rms(d, f, s, n, friction) for n in range(1, top + 1)}
    if order == "auto":
        order = lowest_near_best(scores)
    order = int(order)
    cf, h = _solve(d, f, s, order, friction)
    if h < 0:  # friction cannot push the way the block slides: a fit artefact, drop the term
        cf, h = _solve(d, f, s, order, False)
    spring = f - h * s
    cd = np.polyfit(spring, d, order)
    resid = f - np.polyval(cf, d) - h * s
    rd = d - np.polyval(cd, spring)
    return ForceFit(cf, cd, h, float(np.sqrt(np.mean(resid**2))), float(np.max(np.abs(resid))),
                    float(np.sqrt(np.mean(rd**2))), order, order, scores)


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
