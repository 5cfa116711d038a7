"""Levenberg-Marquardt for the fitters' small nonlinear least-squares problems, numpy only.

    x, cost = minimize(residual, jacobian, x0)                # unbounded
    x, cost = minimize(residual, jacobian, x0, lo, hi)        # a box: projected steps

Every fitter here (the BCM's log-weights, the PWL table's knot positions, PCHIP's node values)
searches at most a few tens of unknowns, so a step is a few tiny dense solves. It is written
out rather than taken from scipy's least_squares for two reasons:
- scipy's bookkeeping cost the BCM fit ten times its model evaluation;
- scipy 1.15 to 1.17 (method="lm", a C translation of MINPACK) read one element past the end
  of the Jacobian in qrfac's column-norm refresh (fixed by scipy commit 8c2790c, in 1.18, which
  needs Python 3.12). The refresh fires when a column is nearly a combination of the others, as
  when a PWL knot barely matters, so the knots depended on whatever lay next in memory: the same
  points gave knots 1e-8 to 1e-3 apart within one process. numpy alone repeats exactly.
"""

import numpy as np


def minimize(residual, jacobian, x0, lo=None, hi=None, max_iter=200, rtol=1e-7, max_evals=None):
    """Minimise sum(residual(x)**2); returns (x, that sum).

    residual(x) -> (m,) array, jacobian(x) -> (m, n) array. With lo and hi (arrays or scalars)
    every trial point is clipped into the box and a variable the gradient presses against its
    bound is held there for that step. Damping is Marquardt's (the normal matrix's diagonal).
    Stops after two quiet steps in a row (the sum falls by at most rtol of itself, or no
    variable moves by 1e-4), when no damping finds a lower sum, after max_iter steps, or after
    max_evals evaluations of residual.
    """
    lo = -np.inf if lo is None else lo
    hi = np.inf if hi is None else hi
    x = np.clip(np.asarray(x0, dtype=float), lo, hi)
    r = residual(x)
    cost = float(r @ r)
    if x.size == 0:
        return x, cost
    evals, lam, quiet = 1, 1e-3, 0
    for _ in range(max_iter):
        jac = jacobian(x)
        grad, hess = jac.T @ r, jac.T @ jac
        # a variable pressed against its bound by the gradient stays there this step
        free = ~(((x <= lo) & (grad > 0)) | ((x >= hi) & (grad < 0)))
        if not free.any():
            break
        hf, gf = hess[np.ix_(free, free)], grad[free]
        damp = np.diag(np.diag(hf)) + 1e-12 * np.eye(gf.size)
        while lam < 1e12:
            step = np.zeros_like(x)
            try:
                step[free] = -np.linalg.solve(hf + lam * damp, gf)
            except np.linalg.LinAlgError:
                lam *= 10
                continue
            trial = np.clip(x + step, lo, hi)
            rt = residual(trial)
            evals += 1
            ct = float(rt @ rt)
            if ct < cost or (max_evals is not None and evals >= max_evals):
                break
            lam *= 4
        else:
            break
        if not ct < cost:
            break
        gain, moved = cost - ct, float(np.max(np.abs(trial - x)))
        x, r, cost = trial, rt, ct
        lam = max(lam / 5, 1e-12)
        quiet = quiet + 1 if (gain <= rtol * cost or moved < 1e-4) else 0
        if quiet >= 2 or (max_evals is not None and evals >= max_evals):
            break
    return x, cost


def forward_difference_jacobian(residual, rel_step=1e-7):
    """jacobian(x) for minimize() by forward differences, for a residual with no analytic one."""

    def jacobian(x):
        r0 = residual(x)
        cols = []
        for i in range(x.size):
            h = rel_step * max(abs(float(x[i])), 1.0)
            xh = x.copy()
            xh[i] += h
            cols.append((residual(xh) - r0) / h)
        return np.stack(cols, axis=1)

    return jacobian
