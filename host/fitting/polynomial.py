"""Polynomial calibrations (the paper's PCM baseline): scaled power basis, raw polyfit, Chebyshev.

Three ways to fit the same order-n polynomial by least squares. They differ only in how the
problem is conditioned, which is the point of keeping all three:

- `fit_pcm`: x is mapped to u = (x - lx) / rx in [0, 1] first; a fair PCM baseline.
- `fit_pcm_raw`: `numpy.polyfit` on raw x, as the paper's MATLAB `polyfit` did. On ADC codes
  (x up to 4095) the Vandermonde matrix has a condition number of 1e30+ at order 10; polyfit
  survives because it scales columns internally, but the coefficients themselves span dozens
  of decades and are useless in float32 on a board. The note records the condition number.
- `fit_chebyshev`: `numpy.polynomial.Chebyshev.fit` (x mapped to [-1, 1], Chebyshev basis),
  the best-conditioned of the three.

Coefficient dicts (firmware does not run these models):
- pcm: {"lx", "rx", "coef"}: y = sum coef[i] * u**i, u = (x - lx) / rx (ascending powers).
- pcm-raw: {"coef"}: numpy.polyval order (highest power first) on raw x.
- cheb: {"domain": [lo, hi], "coef"}: numpy Chebyshev series on x mapped from domain to [-1, 1].
n_params = order + 1 for all three.
"""

import warnings

import numpy as np
from numpy.polynomial import Chebyshev
from numpy.polynomial import polynomial as P

from host.fitting.fit_result import FitResult


def _check(x, y, order):
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    order = int(order)
    if order < 0:
        raise ValueError("polynomial order must be >= 0, got %d" % order)
    if len(x) < order + 1:
        raise ValueError("order %d needs at least %d samples, got %d" % (order, order + 1, len(x)))
    return x, y, order


def _x_scale(x):
    lx = float(x.min())
    rx = float(x.max() - lx) or 1.0
    return lx, rx


def fit_pcm(x, y, order, **options):
    """Order-n polynomial on x scaled to [0, 1], by SVD least squares (numpy.linalg.lstsq)."""
    x, y, order = _check(x, y, order)
    lx, rx = _x_scale(x)
    u = (x - lx) / rx
    vander = P.polyvander(u, order)
    # Column equilibration: on [0, 1] the high powers are tiny near 0; scaling each column to
    # unit norm keeps the SVD's relative cutoff from discarding them.
    norms = np.linalg.norm(vander, axis=0)
    norms[norms == 0] = 1.0
    sol, _, rank, sv = np.linalg.lstsq(vander / norms, y, rcond=None)
    coef = sol / norms
    notes = []
    if rank < order + 1:
        notes.append("rank-deficient design (rank %d of %d): too few distinct x" % (rank, order + 1))

    def curve(xq, coef=coef, lx=lx, rx=rx):
        return P.polyval((np.asarray(xq, dtype=float) - lx) / rx, coef)

    return FitResult(
        model="pcm",
        order=order,
        n_params=order + 1,
        coefficients={"lx": lx, "rx": rx, "coef": [float(c) for c in coef]},
        x_range=(float(x.min()), float(x.max())),
        curve=curve,
        notes=notes,
    )


def raw_condition_number(x, order):
    """2-norm condition number of the raw-x Vandermonde matrix (what the paper's polyfit faces)."""
    vander = np.vander(np.asarray(x, dtype=float), int(order) + 1)
    with np.errstate(all="ignore"):
        return float(np.linalg.cond(vander))


def fit_pcm_raw(x, y, order, **options):
    """The paper's PCM: numpy.polyfit of order n on raw x (highest power first)."""
    x, y, order = _check(x, y, order)
    notes = []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        coef = np.polyfit(x, y, order)
    if any("conditioned" in str(w.message) for w in caught):
        notes.append("numpy.polyfit warned: poorly conditioned on raw x (use pcm or cheb)")
    cond = raw_condition_number(x, order)
    notes.append("raw-x Vandermonde condition number %.3g" % cond)

    def curve(xq, coef=coef):
        return np.polyval(coef, np.asarray(xq, dtype=float))

    return FitResult(
        model="pcm-raw",
        order=order,
        n_params=order + 1,
        coefficients={"coef": [float(c) for c in coef]},
        x_range=(float(x.min()), float(x.max())),
        curve=curve,
        notes=notes,
    )


def fit_chebyshev(x, y, order, **options):
    """Chebyshev series of order n (numpy.polynomial.Chebyshev.fit, x mapped to [-1, 1])."""
    x, y, order = _check(x, y, order)
    lo, hi = float(x.min()), float(x.max())
    domain = [lo, hi] if hi > lo else [lo, lo + 1.0]
    series = Chebyshev.fit(x, y, order, domain=domain)

    return FitResult(
        model="cheb",
        order=order,
        n_params=order + 1,
        coefficients={"domain": domain, "coef": [float(c) for c in series.coef]},
        x_range=(lo, hi),
        curve=series,
    )
