"""Piecewise-linear calibrations: a lookup table (fixed knots) and free-knot segments.

Both return {"knots_x": [...], "knots_y": [...]} (x increasing; linear between knots, clamped
outside), the form the firmware's fixed-point `pwl` runs.

- `fit_lut(x, y, k)`: k knots evenly spaced over the x range; the values are the linear least
  squares solution on the hat (linear B-spline) basis. n_params = k (the positions are implied).
- `fit_pwl(x, y, k)`: k knots whose k - 2 interior positions are optimised (the ends stay at
  the x range). For given positions the values are again linear least squares (variable
  projection), so only the positions are searched: `scipy.optimize.least_squares` over the
  sorted interior positions from several starts (evenly spaced, a dynamic-programming
  segmentation, seeded random ones). n_params = 2k - 2 (k - 2 positions + k values).
"""

import numpy as np
from scipy.optimize import least_squares

from host.fit_result import FitResult

# Weight of the slope-change penalty relative to the data term. It only decides values that the
# data leave free (a knot span with no samples): those knots then lie on the straight line
# through their neighbours instead of the minimum-norm (zero) value.
_TIE_BREAK = 1e-9


def hat_weights(x, knots_x):
    """For each x: the left knot index j and the share w of knot j + 1 (x clamped to the range)."""
    kx = np.asarray(knots_x, dtype=float)
    xc = np.clip(x, kx[0], kx[-1])
    j = np.clip(np.searchsorted(kx, xc, side="right") - 1, 0, len(kx) - 2)
    h = kx[j + 1] - kx[j]
    w = np.where(h > 0, (xc - kx[j]) / np.where(h > 0, h, 1.0), 0.0)
    return j, w


def lsq_knot_values(x, y, knots_x):
    """Least-squares knot values of a piecewise-linear curve with the given knot positions."""
    kx = np.asarray(knots_x, dtype=float)
    k = len(kx)
    j, w = hat_weights(x, kx)
    a = 1.0 - w
    # Normal equations of the hat basis: tridiagonal, assembled by bincount in O(m).
    diag = np.bincount(j, a * a, k) + np.bincount(j + 1, w * w, k)
    off = np.bincount(j, a * w, k - 1)
    rhs = np.bincount(j, a * y, k) + np.bincount(j + 1, w * y, k)
    normal = np.diag(diag) + np.diag(off, 1) + np.diag(off, -1)
    if k > 2:
        # Slope-change rows: zero for any straight line through the knots (see _TIE_BREAK).
        h = np.maximum(np.diff(kx), 1e-12 * max(kx[-1] - kx[0], 1.0))
        mean_h = (kx[-1] - kx[0]) / (k - 1) or 1.0
        rows = np.zeros((k - 2, k))
        idx = np.arange(k - 2)
        rows[idx, idx] = mean_h / h[:-1]
        rows[idx, idx + 1] = -mean_h / h[:-1] - mean_h / h[1:]
        rows[idx, idx + 2] = mean_h / h[1:]
        normal = normal + _TIE_BREAK * max(diag.max(), 1.0) * (rows.T @ rows)
    try:
        return np.linalg.solve(normal, rhs)
    except np.linalg.LinAlgError:
        return np.linalg.lstsq(normal, rhs, rcond=None)[0]


def pwl_curve(knots_x, knots_y):
    """Callable linear interpolation through the knots, clamped to the end values outside."""
    kx = np.asarray(knots_x, dtype=float)
    ky = np.asarray(knots_y, dtype=float)

    def curve(xq):
        return np.interp(np.asarray(xq, dtype=float), kx, ky)

    return curve


def _check(x, y, k):
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    k = int(k)
    if k < 2:
        raise ValueError("a piecewise-linear curve needs at least 2 knots, got %d" % k)
    if x[-1] <= x[0]:
        raise ValueError("x must span a range")
    return x, y, k


def _result(model, k, n_params, kx, ky, notes=()):
    return FitResult(
        model=model,
        order=k,
        n_params=n_params,
        coefficients={"knots_x": [float(v) for v in kx], "knots_y": [float(v) for v in ky]},
        x_range=(float(kx[0]), float(kx[-1])),
        curve=pwl_curve(kx, ky),
        notes=list(notes),
    )


def fit_lut(x, y, order, **options):
    """Lookup table: `order` evenly spaced knots, values by linear least squares."""
    x, y, k = _check(x, y, order)
    kx = np.linspace(x[0], x[-1], k)
    return _result("lut", k, k, kx, lsq_knot_values(x, y, kx))


def segmentation_start(x, y, n_segments, n_grid=64):
    """Interior breakpoints of the best DISCONTINUOUS n-segment line fit on a grid (by DP).

    Separable, hence exact on the grid and fast; the continuous fit is then refined from it.
    """
    grid = np.unique(np.quantile(x, np.linspace(0.0, 1.0, n_grid + 1)))
    g = len(grid)
    if g - 1 < n_segments:
        return None
    # Prefix sums of centred data give the least-squares line SSE of any index range in O(1).
    xc = (x - x.mean()) / (np.ptp(x) or 1.0)
    yc = (y - y.mean()) / (np.ptp(y) or 1.0)
    zero = np.zeros(1)
    sums = [np.concatenate([zero, np.cumsum(v)]) for v in (np.ones_like(xc), xc, yc, xc * xc, xc * yc, yc * yc)]
    lo_i = np.searchsorted(x, grid, side="left")
    hi_i = np.searchsorted(x, grid, side="right")
    a_i, b_i = lo_i[:, None], hi_i[None, :]
    n, sx, sy, sxx, sxy, syy = (s[b_i] - s[a_i] for s in sums)
    with np.errstate(divide="ignore", invalid="ignore"):
        vxx = sxx - sx * sx / n
        vxy = sxy - sx * sy / n
        vyy = syy - sy * sy / n
        sse = vyy - np.where(vxx > 1e-15, vxy * vxy / vxx, 0.0)
    sse = np.where(n > 0, np.maximum(sse, 0.0), 0.0)
    forward = np.triu(np.ones((g, g), dtype=bool), 1)
    cost = np.where(forward, sse, np.inf)
    best = cost[0].copy()  # best[b]: one segment from grid[0] to grid[b]
    back = []
    for _ in range(n_segments - 1):
        total = best[:, None] + cost
        arg = np.argmin(total, axis=0)
        back.append(arg)
        best = total[arg, np.arange(g)]
    cuts, b = [], g - 1
    for arg in reversed(back):
        b = arg[b]
        cuts.append(grid[b])
    return np.array(sorted(cuts))


def _refine(x, y, lo, span, u0):
    """Least-squares refinement of interior knot positions u in (0, 1) (values projected out)."""

    def knots(u):
        return np.concatenate([[lo], lo + span * np.sort(u), [lo + span]])

    def residuals(u):
        kx = knots(u)
        return pwl_curve(kx, lsq_knot_values(x, y, kx))(x) - y

    u0 = np.clip(u0, 1e-6, 1 - 1e-6)
    sol = least_squares(residuals, u0, bounds=(0.0, 1.0), diff_step=1e-4, xtol=1e-9, ftol=1e-12, max_nfev=200)
    return float(np.sum(sol.fun ** 2)), knots(sol.x)


def fit_pwl(x, y, order, starts=4, seed=0, **options):
    """Free-knot piecewise-linear curve with `order` knots (interior positions optimised)."""
    x, y, k = _check(x, y, order)
    lo, hi = float(x[0]), float(x[-1])
    span = hi - lo
    if k == 2:
        kx = np.array([lo, hi])
        return _result("pwl", k, 2, kx, lsq_knot_values(x, y, kx))
    n_inner = k - 2
    candidates = [np.linspace(0, 1, k)[1:-1]]
    dp = segmentation_start(x, y, k - 1)
    if dp is not None:
        candidates.append((dp - lo) / span)
    rng = np.random.default_rng(seed)
    while len(candidates) < max(int(starts), 1):
        candidates.append(np.sort(rng.uniform(0, 1, n_inner)))
    best = None
    for u0 in candidates:
        sse, kx = _refine(x, y, lo, span, u0)
        if best is None or sse < best[0]:
            best = (sse, kx)
    kx = best[1]
    notes = ["knot positions optimised from %d starts (even, DP segmentation, random)" % len(candidates)]
    return _result("pwl", k, 2 * k - 2, kx, lsq_knot_values(x, y, kx), notes)
