"""The BCM: a rational Bernstein (Bezier) calibration curve of degree n, and how it is fitted.

Model (the paper's section 2, the paper's eq. 2), with t = (x - lx) / rx clamped to [0, 1]:

    f(x) = sum_i B_i(t) w_i p_i / sum_i B_i(t) w_i,    B_i(t) = C(n, i) t^i (1 - t)^(n - i)

p_i are the handles (reference units, mm for our pots) and w_i > 0 the weights. The paper writes
the binomial as C(n+1, i-1) with i = 1..n+1; a fixed positive factor per term is absorbed by the
weights, so this module uses the standard Bernstein form. Multiplying every weight by one
constant changes nothing, so the stored form has w_0 = 1.

Fitting is variable projection: for fixed weights the curve is linear in the handles (the
functions phi_i = B_i w_i / sum_j B_j w_j are a partition of unity), so the handles are solved
exactly by (bounded) linear least squares and only the log-weights are searched, by a bounded
Levenberg-Marquardt (host/fitting/levenberg_marquardt.py, Kaufman's Jacobian) from a few starts.

- bounds="data" (default): w_0 = 1, log-weights in +-ln 60 (ratios 1/60..60), handles within the
  reference range widened by 10 % of it on each side.
- bounds="paper": the paper's literal box, handles in [0, 60], every weight (w_0 too) in [1, 60].
  That box keeps the exact scale direction of the weights, which the optimiser has to live with.

Monotonicity: the curve is checked at every input it can meet (every integer code when x are
ADC codes, else a dense grid). Only when it reverses is the fit redone with non-decreasing (or
non-increasing) handles, which with positive weights guarantees a monotone curve; a note says so.
"""

import math

import numpy as np
from scipy.linalg import solve_triangular
from scipy.optimize import differential_evolution, lsq_linear
from scipy.special import comb

from host.fitting.fit_result import FitResult, check_points
from host.fitting.levenberg_marquardt import minimize

LN60 = math.log(60.0)
WIDEN = 0.10  # handle bounds: reference range widened by this share of it on each side
PAPER_BOX = (0.0, 60.0)  # the paper's bounds for handles and weights


def bernstein(t, n):
    """Matrix of the n+1 Bernstein polynomials of degree n at the points t (rows)."""
    t = np.asarray(t, dtype=float)[:, None]
    i = np.arange(n + 1)
    return comb(n, i) * t**i * (1.0 - t) ** (n - i)


def evaluate(coefficients, x):
    """The BCM curve described by a coefficient dict {lx, rx, weights, handles} at inputs x."""
    w = np.asarray(coefficients["weights"], dtype=float)
    p = np.asarray(coefficients["handles"], dtype=float)
    t = np.clip((np.asarray(x, dtype=float) - coefficients["lx"]) / coefficients["rx"], 0.0, 1.0)
    bw = bernstein(np.atleast_1d(t).ravel(), len(w) - 1) * w
    out = (bw @ p) / bw.sum(axis=1)
    return out.reshape(np.shape(t)) if np.ndim(t) else float(out[0])


def elevate(coefficients, degree):
    """The same curve written with more handles (exact degree elevation in homogeneous form)."""
    w = np.asarray(coefficients["weights"], dtype=float)
    q = w * np.asarray(coefficients["handles"], dtype=float)
    while len(w) - 1 < degree:
        m = len(w)  # new degree
        a = np.arange(m + 1) / m
        w = np.concatenate([w, [0.0]]) * (1 - a) + np.concatenate([[0.0], w]) * a
        q = np.concatenate([q, [0.0]]) * (1 - a) + np.concatenate([[0.0], q]) * a
    return dict(coefficients, weights=list(w / w[0]), handles=list(q / w))


class _Projection:
    """The reduced problem: residual and Jacobian as functions of the searched log-weights."""

    def __init__(self, basis, y, free, handle_lo, handle_hi, shape=0, wt=None):
        self.wt = np.ones(len(y)) if wt is None else wt  # sqrt of how many samples a row stands for
        self.basis, self.y = basis, y * self.wt
        self.free = free  # indices of the weights being searched (others stay 1)
        self.lo, self.hi = handle_lo, handle_hi
        self.shape = shape  # 0 free handles, +1 non-decreasing, -1 non-increasing
        m = basis.shape[1]
        self.steps = np.tril(np.ones((m, m))) * (shape if shape else 1)
        self.steps[:, 0] = 1.0
        # bounds on the solved variables: the handles, or (first handle, increments >= 0)
        self.lb, self.ub = np.full(m, float(handle_lo)), np.full(m, float(handle_hi))
        if shape:
            self.lb[1:], self.ub[1:] = 0.0, np.inf
        self._key = None

    def weights(self, theta):
        w = np.ones(self.basis.shape[1])
        w[self.free] = np.exp(theta)
        return w

    def solve(self, theta):
        """Handles for these weights; caches phi, handles, fit and whether a bound is active."""
        key = np.asarray(theta, dtype=float).tobytes()
        if key == self._key:
            return
        bw = self.basis * self.weights(theta)
        phi = bw / bw.sum(axis=1)[:, None]
        design = (phi if self.shape == 0 else phi @ self.steps) * self.wt[:, None]
        # normal equations on the small Gram matrix: tall LAPACK calls (QR, SVD) are slow
        # under a threaded BLAS on a busy machine, small solves and matmuls are not
        gram = design.T @ design
        rhs = design.T @ self.y
        try:
            z = np.linalg.solve(gram, rhs)
        except np.linalg.LinAlgError:  # too few distinct inputs for this degree: least norm
            z = np.linalg.lstsq(gram, rhs, rcond=None)[0]
        if np.any(z < self.lb) or np.any(z > self.ub):
            try:
                # same minimiser as the tall problem: |A z - y|^2 = |L' z - L^-1 A'y|^2 + const
                chol = np.linalg.cholesky(gram)
                z = lsq_linear(chol.T, solve_triangular(chol, rhs, lower=True), bounds=(self.lb, self.ub),
                               method="bvls").x
            except np.linalg.LinAlgError:
                z = lsq_linear(design, self.y, bounds=(self.lb, self.ub), method="bvls").x
        tiny = 1e-10
        inactive = (z > self.lb + tiny) & (z < self.ub - tiny)
        free_cols = (design[:, inactive], gram[np.ix_(inactive, inactive)]) if inactive.any() else None
        p = z if self.shape == 0 else self.steps @ z
        self._key, self.phi, self.p, self.free_cols = key, phi, p, free_cols
        self.f = phi @ p

    def residual(self, theta):
        self.solve(theta)
        return self.f * self.wt - self.y

    def jacobian(self, theta):
        self.solve(theta)
        # d f / d log w_k at fixed handles is phi_k (p_k - f); with the handles at their
        # optimum, project out what the handles still free to move would absorb (Kaufman).
        g = self.phi[:, self.free] * ((self.p[self.free][None, :] - self.f[:, None]) * self.wt[:, None])
        if self.free_cols is None:
            return g
        a, gram = self.free_cols
        g = g - a @ np.linalg.lstsq(gram, a.T @ g, rcond=None)[0]
        if self.shape == 0 and a.shape[1] == self.phi.shape[1]:
            # Golub-Pereyra's second term, -(A+)' (dA_k)' r: it matters here because a low-degree
            # curve leaves a large systematic residual, and without it steps zigzag near the optimum
            r = self.f * self.wt - self.y
            u = self.phi[:, self.free] * (self.wt * r)[:, None]
            v = -(self.phi.T @ u)
            v[self.free, np.arange(self.free.size)] += u.sum(axis=0)
            g = g - a @ np.linalg.lstsq(gram, v, rcond=None)[0]
        return g


def _starts(n_free, lo, hi, count, seed, interior):
    """Start points: all weights equal, heavy interior weights (x4, x20), one seeded random; past
    four: light interior weights (/4), a heavy first end, a heavy last end, then more random."""
    out = [np.clip(np.zeros(n_free), lo, hi)]
    if interior.any():
        for factor in (4.0, 20.0):
            out.append(np.clip(np.where(interior, math.log(factor), 0.0), lo, hi))
    rng = np.random.default_rng(seed)
    out.append(rng.uniform(lo + 0.25 * (hi - lo), hi - 0.25 * (hi - lo), n_free))
    if interior.any():
        out.append(np.clip(np.where(interior, -math.log(4.0), 0.0), lo, hi))
    last = ~interior  # the w_n entry (w_0 is fixed at 1 in the data box)
    out.append(np.clip(np.full(n_free, -math.log(20.0)), lo, hi))  # a heavy first end
    out.append(np.clip(np.where(last, math.log(20.0), 0.0), lo, hi))  # a heavy last end
    while len(out) < count:
        out.append(rng.uniform(lo + 0.25 * (hi - lo), hi - 0.25 * (hi - lo), n_free))
    return out[: max(1, count)]


def _setup(x, y, order, bounds):
    if order < 1:
        raise ValueError("BCM degree must be at least 1")
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    lx, rx = float(np.min(x)), float(np.ptp(x))
    if rx <= 0:
        raise ValueError("x must span a range")
    # fit in normalised reference units (the curve commutes with affine maps of y)
    y0, ys = float(np.min(y)), float(np.ptp(y)) or 1.0
    yn = (y - y0) / ys
    basis = bernstein((x - lx) / rx, order)
    idx = np.arange(order + 1)
    if bounds == "data":
        free, lo, hi = idx[1:], -LN60, LN60
        plo, phi = -WIDEN, 1.0 + WIDEN
    elif bounds == "paper":
        free, lo, hi = idx, 0.0, LN60
        plo, phi = (PAPER_BOX[0] - y0) / ys, (PAPER_BOX[1] - y0) / ys
    else:
        raise ValueError("bounds must be 'data' or 'paper', not %r" % (bounds,))
    interior = (free > 0) & (free < order)
    return lx, rx, y0, ys, yn, basis, free, lo, hi, plo, phi, interior


def _local(problem, theta0, lo, hi, max_iter=200, rtol=1e-7):
    """Projected Levenberg-Marquardt on the log-weights (host/fitting/levenberg_marquardt.py);
    returns (theta, cost) and leaves the problem's cache at the answer."""
    theta, cost = minimize(problem.residual, problem.jacobian, theta0, lo, hi, max_iter, rtol)
    problem.residual(theta)
    return theta, cost


def _result(order, bounds, lx, rx, y0, ys, problem, theta, notes):
    problem.solve(theta)
    w = problem.weights(theta)
    w = w / w[0]
    coeffs = {
        "lx": lx,
        "rx": rx,
        "weights": [float(v) for v in w],
        "handles": [float(y0 + ys * v) for v in problem.p],
    }
    return FitResult(
        model="bcm",
        order=order,
        n_params=2 * order + 1,  # n+1 handles and n weight ratios
        coefficients=coeffs,
        x_range=(lx, lx + rx),
        curve=lambda xs, c=coeffs: evaluate(c, xs),
        notes=notes,
    )


def reverses(coefficients, x):
    """0 when the curve is monotone over every input of x's kind, else the largest step back."""
    f = evaluate(coefficients, check_points(x))
    d = np.diff(f)
    trend = 1.0 if f[-1] >= f[0] else -1.0
    worst = float(np.max(-trend * d)) if d.size else 0.0
    return max(0.0, worst - 1e-12 * (abs(f[-1] - f[0]) or 1.0))


def _binned(t, y, max_points):
    """Equal-count bin means of sorted data and sqrt(count) row weights (for the weight search)."""
    if t.size <= max_points:
        return t, y, None
    edges = np.linspace(0, t.size, max_points + 1).astype(int)
    counts = np.diff(edges).astype(float)
    tm = np.add.reduceat(t, edges[:-1]) / counts
    ym = np.add.reduceat(y, edges[:-1]) / counts
    return tm, ym, np.sqrt(counts)


def _search(make, starts, lo, hi):
    best = None
    for theta0 in starts:
        theta, cost = _local(make(), theta0, lo, hi)
        if best is None or cost < best[1]:
            best = (theta, cost)
    return best[0]


def fit_bcm(x, y, order, bounds="data", starts=None, seed=0, monotone="check", max_search_points=4000,
            warm=None):
    """Fit a degree-`order` BCM to sorted (x, y); monotone = "check" | "force" | "off".

    `starts` local searches (default 4 up to degree 3, 7 above, where more basins appear).
    Above `max_search_points` samples the weights are searched on that many bin means (the
    handles are always solved on every sample), which keeps 30,000-sample sweeps fast.
    `warm`: a fit of lower degree to the same data (a FitResult or its coefficients), elevated
    exactly and used as one more start. From degree 4 up, without it, the degree n-1 fit is made
    here first (which repeats every degree from 3 up); a caller that fits degree after degree,
    like `host compare`, passes its previous fit instead and does each degree once.
    """
    lx, rx, y0, ys, yn, basis, free, lo, hi, plo, phi, interior = _setup(x, y, order, bounds)
    starts = (4 if order <= 3 else 7) if starts is None else int(starts)
    t = (np.asarray(x, dtype=float) - lx) / rx
    tb, yb, wt = _binned(t, yn, int(max_search_points))
    basis_b = basis if wt is None else bernstein(tb, order)
    notes = [] if wt is None else ["weights searched on %d bin means of the %d samples" % (tb.size, t.size)]
    start_points = _starts(free.size, lo, hi, starts, seed, interior)
    if warm is None and order >= 4:
        # The degree n-1 fit, elevated exactly, sits in the basin the lower degree found (the
        # generic starts can miss it at higher degree) and its handle solve already matches that
        # curve, so this start is never worse than that fit. The lower fit is itself warm-started
        # the same way down to degree 3, so above degree 4 it uses 1 generic start to keep the
        # chain cheap. Degrees 1-3 stay as they were.
        warm = fit_bcm(x, y, order - 1, bounds, 1 if order > 4 else None, seed, "off", max_search_points)
    if warm is not None:
        previous = getattr(warm, "coefficients", warm)
        if len(previous["weights"]) - 1 >= order:
            raise ValueError("a warm start must have a lower degree than %d" % order)
        w = np.asarray(elevate(previous, order)["weights"])
        start_points.append(np.clip(np.log(w[free] / (w[0] if bounds == "data" else w.min())), lo, hi))
    theta = None
    if monotone != "force":
        theta = _search(lambda: _Projection(basis_b, yb, free, plo, phi, wt=wt), start_points, lo, hi)
        result = _result(order, bounds, lx, rx, y0, ys, _Projection(basis, yn, free, plo, phi), theta, notes)
        if monotone == "off":
            return result
        back = reverses(result.coefficients, x)
        if back == 0.0:
            return result
        notes.append(
            "the best curve reversed by up to %.3g reference units, so it was refitted with monotone handles" % back
        )
    trend = 1 if np.polyfit(t, yn, 1)[0] >= 0 else -1
    seeds = start_points + ([theta] if theta is not None else [])
    theta_m = _search(lambda: _Projection(basis_b, yb, free, plo, phi, shape=trend, wt=wt), seeds, lo, hi)
    if monotone == "force":
        notes.append("handles constrained to be monotone")
    return _result(order, bounds, lx, rx, y0, ys, _Projection(basis, yn, free, plo, phi, shape=trend), theta_m, notes)


def fit_bcm_global(x, y, order, bounds="data", maxiter=60, popsize=12, seed=0, tol=1e-8):
    """Slow reference fit: differential evolution over the log-weights, then a local polish."""
    lx, rx, y0, ys, yn, basis, free, lo, hi, plo, phi, _ = _setup(x, y, order, bounds)
    problem = _Projection(basis, yn, free, plo, phi)

    def cost(theta):
        return float(np.sum(problem.residual(theta) ** 2))

    de = differential_evolution(
        cost, [(lo, hi)] * free.size, maxiter=maxiter, popsize=popsize, seed=seed, tol=tol, polish=False
    )
    theta, _ = _local(problem, np.clip(de.x, lo, hi), lo, hi)
    if cost(theta) > de.fun:
        theta = de.x
    return _result(order, bounds, lx, rx, y0, ys, problem, theta, ["global search (differential evolution)"])
