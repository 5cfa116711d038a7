"""Piecewise-linear calibrations: a lookup table (fixed knots) and free-knot segments.

Both return {"knots_x": [...], "knots_y": [...]} (x increasing; linear between knots, clamped
outside), the form the firmware's fixed-point `pwl` runs.

- `fit_lut(x, y, k)`: k knots evenly spaced over the x range; the values are the linear least
  squares solution on the hat (linear B-spline) basis. n_params = k (the positions are implied).
- `fit_pwl(x, y, k)`: k knots whose k - 2 interior positions are optimised (the ends stay at
  the x range). For given positions the values are again linear least squares (variable
  projection), so only the positions are searched: Levenberg-Marquardt
  (host/fitting/levenberg_marquardt.py) with an analytic Jacobian over log-gaps (knots stay ordered)
  from several starts (evenly spaced, a dynamic-programming segmentation, seeded random ones,
  and optionally a smaller fit's knots grown by splitting its worst span). Long sweeps are
  searched on bin means; values are always solved on every sample. The even start is kept if
  nothing beats it, so pwl-k is never worse than lut-k. n_params = 2k - 2 (k - 2 positions +
  k values).
"""

import numpy as np
from scipy.optimize import lsq_linear

from host.fitting.fit_result import FitResult
from host.fitting.levenberg_marquardt import minimize

# Weight of the slope-change penalty relative to the data term. It only decides values that the
# data leave free (a knot span with no samples): those knots then lie on the straight line
# through their neighbours instead of the minimum-norm (zero) value.
_TIE_BREAK = 1e-10


def hat_weights(x, knots_x):
    """For each x: the left knot index j and the share w of knot j + 1 (x clamped to the range)."""
    kx = np.asarray(knots_x, dtype=float)
    xc = np.clip(x, kx[0], kx[-1])
    j = np.clip(np.searchsorted(kx, xc, side="right") - 1, 0, len(kx) - 2)
    h = kx[j + 1] - kx[j]
    w = np.where(h > 0, (xc - kx[j]) / np.where(h > 0, h, 1.0), 0.0)
    return j, w


def hat_matrix(x, knots_x):
    """The dense hat (linear B-spline) basis: row i holds x[i]'s weights on each knot."""
    j, w = hat_weights(x, knots_x)
    a = np.zeros((len(x), len(knots_x)))
    rows = np.arange(len(x))
    a[rows, j] += 1.0 - w
    a[rows, j + 1] += w
    return a


def _normal_matrix(j, w, kx, wt=1.0):
    """A^T W A of the hat basis (tridiagonal, by bincount in O(m)) plus the tie-break penalty."""
    k = len(kx)
    a = 1.0 - w
    diag = np.bincount(j, wt * a * a, k) + np.bincount(j + 1, wt * w * w, k)
    off = np.bincount(j, wt * a * w, k - 1)
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
    return normal


def _hat_transpose(j, w, k, columns):
    """A^T @ columns for the hat basis A (columns: m x c)."""
    c = columns.shape[1]
    flat = (j[:, None] * c + np.arange(c)[None, :]).ravel()
    left = np.bincount(flat, ((1.0 - w)[:, None] * columns).ravel(), k * c)
    right = np.bincount(flat + c, (w[:, None] * columns).ravel(), k * c)
    return (left + right).reshape(k, c)


def _solve(normal, rhs):
    try:
        return np.linalg.solve(normal, rhs)
    except np.linalg.LinAlgError:
        return np.linalg.lstsq(normal, rhs, rcond=None)[0]


def lsq_knot_values(x, y, knots_x):
    """Least-squares knot values of a piecewise-linear curve with the given knot positions."""
    kx = np.asarray(knots_x, dtype=float)
    k = len(kx)
    j, w = hat_weights(x, kx)
    rhs = np.bincount(j, (1.0 - w) * y, k) + np.bincount(j + 1, w * y, k)
    return _solve(_normal_matrix(j, w, kx), rhs)


def knot_values(x, y, knots_x, monotone="check", notes=None):
    """Least-squares knot values; with monotone "check" they follow the data's trend.

    A pot's calibration must never step back, and a piecewise-linear curve is monotone exactly
    when its knot values are. "check" keeps the free values when they already are; otherwise
    (two close knots across the noisy cluster read at an end stop, say) it solves them again as
    a start value plus same-signed increments, a bounded linear least squares, and says so in
    `notes`. "off" (a curve that may turn, such as Df) returns the free values."""
    kx = np.asarray(knots_x, dtype=float)
    v = lsq_knot_values(x, y, kx)
    if monotone == "off":
        return v
    if monotone != "check":
        raise ValueError('monotone must be "check" or "off", not %r' % (monotone,))
    trend = 1.0 if np.polyfit(x, y, 1)[0] >= 0 else -1.0
    if np.all(trend * np.diff(v) >= 0):
        return v
    if notes is not None:
        notes.append("the free knot values stepped back by up to %.3g reference units, so they were solved "
                     "again constrained to the data's trend" % float(np.max(-trend * np.diff(v))))
    k = len(kx)
    basis = hat_matrix(x, kx)
    steps = np.tril(np.ones((k, k)))  # v = steps @ d: d[0] the first value, d[1:] the increments
    steps[:, 1:] *= trend
    lower = np.r_[-np.inf, np.zeros(k - 1)]
    d = lsq_linear(basis @ steps, y, bounds=(lower, np.inf), method="bvls").x
    return steps @ d


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


def fit_lut(x, y, order, monotone="check", **options):
    """Lookup table: `order` evenly spaced knots, values by linear least squares (see knot_values)."""
    x, y, k = _check(x, y, order)
    kx = np.linspace(x[0], x[-1], k)
    notes = []
    return _result("lut", k, k, kx, knot_values(x, y, kx, monotone, notes), notes)


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


def _gaps_to_u(z):
    """Interior positions in (0, 1) from log-gaps z (first gap fixed): always sorted, never equal."""
    g = np.exp(np.clip(np.concatenate([[0.0], z]), -40.0, 40.0))
    c = np.cumsum(g)
    return c[:-1] / c[-1], g, c


def _refine(x, y, wt, lo, span, u0):
    """Gauss-Newton on interior knot positions, values projected out (variable projection).

    Positions are parameterised by log-gaps, so knots stay ordered and distinct. The Jacobian
    is Kaufman's: the partial derivative of the curve in the knot positions, projected onto the
    complement of the hat basis (the values re-solve themselves at every step). `wt` are
    sample weights (counts of binned samples).
    """
    root = np.sqrt(wt)
    u0 = np.clip(np.sort(u0), 1e-6, 1 - 1e-6)
    gaps = np.maximum(np.diff(np.concatenate([[0.0], u0, [1.0]])), 1e-6)
    z0 = np.log(gaps[1:] / gaps[0])
    n_in = len(u0)
    k = n_in + 2

    def state(z):
        u, g, c = _gaps_to_u(z)
        kx = np.concatenate([[lo], lo + span * u, [lo + span]])
        j, w = hat_weights(x, kx)
        normal = _normal_matrix(j, w, kx, wt)
        v = _solve(normal, np.bincount(j, wt * (1.0 - w) * y, k) + np.bincount(j + 1, wt * w * y, k))
        return kx, j, w, normal, v, g, c

    def residuals(z):
        kx, j, w, _, v, _, _ = state(z)
        return root * ((1.0 - w) * v[j] + w * v[j + 1] - y)

    def jacobian(z):
        kx, j, w, normal, v, g, c = state(z)
        h = np.diff(kx)
        slope = np.where(h > 0, np.diff(v) / np.where(h > 0, h, 1.0), 0.0)
        m = len(x)
        dk = np.zeros((m, k))  # d curve / d knot position, for every knot (ends dropped below)
        rows = np.arange(m)
        dk[rows, j + 1] += -slope[j] * w
        dk[rows, j] += -slope[j] * (1.0 - w)
        dk = dk[:, 1:-1]
        coef = _solve(normal, _hat_transpose(j, w, k, wt[:, None] * dk))
        dk = dk - ((1.0 - w)[:, None] * coef[j] + w[:, None] * coef[j + 1])
        # chain rule: u_i = c_i / c_last, g_l = exp(z_l) (l >= 1), d u_i / d z_l = g_(l+1) ([l + 1 <= i] - u_i) / c_last
        u = c[:-1] / c[-1]
        idx = np.arange(n_in)
        du = g[None, 1:] * ((idx[None, :] + 1 <= idx[:, None]).astype(float) - u[:, None]) / c[-1]
        return (root[:, None] * dk * span) @ du

    z, cost = minimize(residuals, jacobian, z0, max_evals=50 * k)
    return cost, state(z)[0]


def binned(x, y, max_points):
    """(x, y, weights): means of consecutive sorted samples, at most max_points of them.

    The knot search on 30,000 samples costs 15x more than on 2,000 and finds the same knots;
    the final values are always solved on every sample.
    """
    m = len(x)
    if m <= max_points:
        return x, y, np.ones(m)
    edges = np.linspace(0, m, max_points + 1).astype(int)
    counts = np.diff(edges).astype(float)
    sx = np.add.reduceat(x, edges[:-1])
    sy = np.add.reduceat(y, edges[:-1])
    return sx / counts, sy / counts, counts


def grow_knots(x, y, knots_x, k):
    """Knot positions for k knots from fewer: split the span with the largest residual SSE."""
    kx = np.asarray(knots_x, dtype=float)
    while len(kx) < k:
        r = pwl_curve(kx, lsq_knot_values(x, y, kx))(x) - y
        j, _ = hat_weights(x, kx)
        sse = np.bincount(j, r * r, len(kx) - 1)
        worst = int(np.argmax(sse))
        kx = np.insert(kx, worst + 1, 0.5 * (kx[worst] + kx[worst + 1]))
    return kx


def fit_pwl(x, y, order, starts=4, seed=0, max_search_points=2000, start_knots=None, monotone="check", **options):
    """Free-knot piecewise-linear curve with `order` knots (interior positions optimised).

    `monotone` as in `knot_values`: the positions are searched free, the final values follow
    the data's trend unless "off".

    `start_knots` (optional): all knot positions of a fit with fewer knots (e.g. the previous
    order in a sweep over orders); they are grown to `order` knots and used as one more start,
    so the fit is never worse than that one.
    """
    x, y, k = _check(x, y, order)
    lo, hi = float(x[0]), float(x[-1])
    span = hi - lo
    even = np.linspace(lo, hi, k)
    if k == 2:
        notes = []
        return _result("pwl", k, 2, even, knot_values(x, y, even, monotone, notes), notes)
    n_inner = k - 2
    xs, ys, wt = binned(x, y, int(max_search_points))
    candidates = [(even[1:-1] - lo) / span]
    dp = segmentation_start(xs, ys, k - 1)
    if dp is not None:
        candidates.append((dp - lo) / span)
    if start_knots is not None and 2 <= len(start_knots) <= k:
        grown = grow_knots(x, y, np.clip(np.sort(start_knots), lo, hi), k)
        candidates.append((grown[1:-1] - lo) / span)
    rng = np.random.default_rng(seed)
    while len(candidates) < max(int(starts), 1) + (start_knots is not None):
        candidates.append(np.sort(rng.uniform(0, 1, n_inner)))
    best = None
    for u0 in candidates:
        sse, kx = _refine(xs, ys, wt, lo, span, u0)
        if best is None or sse < best[0]:
            best = (sse, kx)
    kx = best[1]
    notes = ["knot positions optimised from %d starts (even, DP segmentation, %srandom)"
             % (len(candidates), "grown from the given knots, " if start_knots is not None else "")]
    if len(xs) < len(x):
        notes.append("knot search on %d bin means of the %d samples; values fitted on all" % (len(xs), len(x)))
    # The search only ever improves on its starts; neither binning nor the trend constraint on
    # the final values may undo that, so the knots are chosen by the error of their final
    # values: free values that step back are solved again constrained, which can cost more than
    # a start whose free values did not (a short real curve: 11 knots grown from 10 did worse
    # than the 10, and a sweep over orders rose)
    starts = [kx, even] + ([grown] if start_knots is not None and 2 <= len(start_knots) <= k else [])
    finals = [(kn, knot_values(x, y, kn, monotone)) for kn in starts]
    kx, _ = min(finals, key=lambda f: float(np.sum((pwl_curve(f[0], f[1])(x) - y) ** 2)))
    return _result("pwl", k, 2 * k - 2, kx, knot_values(x, y, kx, monotone, notes), notes)
