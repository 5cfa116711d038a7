"""Spline calibrations: a least-squares cubic spline and a monotone cubic (PCHIP) table.

- `fit_spline(x, y, k)`: cubic B-spline with k knots evenly spaced over the x range (both ends
  included, so k - 2 interior knots), coefficients by least squares
  (`scipy.interpolate.make_lsq_spline`). It has k + 2 coefficients: n_params = k + 2.
  Coefficients {"t": full knot vector, "c": B-spline coefficients, "k": 3}, i.e. the arguments
  of `scipy.interpolate.BSpline`.
- `fit_pchip(x, y, k)`: PCHIP (piecewise cubic Hermite, monotone where the node values are)
  through k nodes evenly spaced over the x range. Node values are found by LEAST SQUARES of
  the PCHIP curve itself: start from the linear least-squares values of the hat basis (the
  `lut` fit), then refine with Levenberg-Marquardt (host/fitting/levenberg_marquardt.py, forward
  differences: PCHIP's slopes depend on the values nonlinearly). n_params = k. Coefficients {"knots_x", "knots_y"}; evaluate with
  `scipy.interpolate.PchipInterpolator(knots_x, knots_y)`, clamped outside the range.
"""

import numpy as np
from scipy.interpolate import BSpline, PchipInterpolator, make_lsq_spline

from host.fitting.fit_result import FitResult
from host.fitting.levenberg_marquardt import forward_difference_jacobian, minimize
from host.fitting.piecewise_linear import lsq_knot_values


def _check(x, y, k, least):
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    k = int(k)
    if k < least:
        raise ValueError("need at least %d knots, got %d" % (least, k))
    if x[-1] <= x[0]:
        raise ValueError("x must span a range")
    return x, y, k


def cubic_knot_vector(lo, hi, k):
    """Full knot vector of a clamped cubic spline with k evenly spaced breakpoints."""
    breaks = np.linspace(lo, hi, k)
    return np.concatenate([[lo] * 3, breaks, [hi] * 3])


def fit_spline(x, y, order, **options):
    """Least-squares cubic spline with `order` evenly spaced knots (ends included)."""
    x, y, k = _check(x, y, order, 2)
    lo, hi = float(x[0]), float(x[-1])
    t = cubic_knot_vector(lo, hi, k)
    n_coef = len(t) - 4
    notes = []
    try:
        spl = make_lsq_spline(x, y, t, k=3)
        c = spl.c
    except (np.linalg.LinAlgError, ValueError):
        # Schoenberg-Whitney fails when a knot span has too few distinct x (sparse real
        # data): fall back to minimum-norm least squares on the same basis.
        design = BSpline.design_matrix(x, t, 3).toarray()
        c = np.linalg.lstsq(design, y, rcond=None)[0]
        notes.append("knot spans with too few samples: minimum-norm least squares used")
    spl = BSpline(t, c, 3, extrapolate=False)

    def curve(xq, spl=spl, lo=lo, hi=hi):
        return spl(np.clip(np.asarray(xq, dtype=float), lo, hi))

    return FitResult(
        model="spline",
        order=k,
        n_params=n_coef,
        coefficients={"t": [float(v) for v in t], "c": [float(v) for v in c], "k": 3},
        x_range=(lo, hi),
        curve=curve,
        notes=notes,
    )


def pchip_curve(knots_x, knots_y):
    """Callable PCHIP through the nodes, clamped to the end values outside the range."""
    interp = PchipInterpolator(knots_x, knots_y, extrapolate=False)
    lo, hi = knots_x[0], knots_x[-1]

    def curve(xq):
        return interp(np.clip(np.asarray(xq, dtype=float), lo, hi))

    return curve


def fit_pchip(x, y, order, **options):
    """PCHIP through `order` evenly spaced nodes; node values by nonlinear least squares."""
    x, y, k = _check(x, y, order, 2)
    lo, hi = float(x[0]), float(x[-1])
    kx = np.linspace(lo, hi, k)
    start = lsq_knot_values(x, y, kx)
    if k > 2:
        scale = max(float(np.ptp(y)), 1e-12)

        def residuals(v):
            return (PchipInterpolator(kx, v * scale)(x) - y) / scale

        v, cost = minimize(residuals, forward_difference_jacobian(residuals), start / scale, rtol=1e-12)
        ky = v * scale
        if cost > np.sum(residuals(start / scale) ** 2):
            ky = start
    else:
        ky = start  # two nodes: PCHIP is the straight line, already the least-squares one

    return FitResult(
        model="pchip",
        order=k,
        n_params=k,
        coefficients={"knots_x": [float(v) for v in kx], "knots_y": [float(v) for v in ky]},
        x_range=(lo, hi),
        curve=pchip_curve(kx, ky),
        notes=["node values: least squares of the PCHIP curve, started from the linear-table fit"],
    )
