"""The noise floor of a sweep, estimated from the data alone (no model fitted).

Gasser, Sroka and Jennen-Steinmetz (Biometrika 1986): on data sorted by x, each interior point
is compared with the straight line through its two neighbours. For a smooth curve that line
cancels the trend, so what is left is noise:

    e_i = a_i y_{i-1} + b_i y_{i+1} - y_i,   a_i = (x_{i+1} - x_i) / (x_{i+1} - x_{i-1}),  b_i = 1 - a_i
    sigma^2 = mean(c_i^2 e_i^2),              c_i^2 = 1 / (a_i^2 + b_i^2 + 1)

(c_i makes each term unbiased for sigma^2). Where both neighbours share the point's x (ADC codes
repeat), the line is their mean: a_i = b_i = 1/2. A sweep measured in both directions is split by
direction first, because hysteresis would otherwise count as noise; the per-direction variances
are pooled by their degrees of freedom.

The result is the standard deviation of the reference-unit scatter about the true curve: the best
RMS any calibration can reach on this sweep. A calibration near it has nothing left to learn.
"""

import numpy as np


def _gsj_sum(x, y):
    """(sum of c_i^2 e_i^2, number of terms) for one sorted run."""
    if x.size < 3:
        return 0.0, 0
    order = np.argsort(x, kind="stable")
    x, y = x[order], y[order]
    width = x[2:] - x[:-2]
    a = np.where(width > 0, (x[2:] - x[1:-1]) / np.where(width > 0, width, 1.0), 0.5)
    b = 1.0 - a
    e = a * y[:-2] + b * y[2:] - y[1:-1]
    c2 = 1.0 / (a * a + b * b + 1.0)
    return float(np.sum(c2 * e * e)), int(e.size)


def estimate_noise(x, y, direction=None):
    """Standard deviation of the noise in y (reference units), from the data alone."""
    x = np.asarray(x, dtype=float).ravel()
    y = np.asarray(y, dtype=float).ravel()
    if x.shape != y.shape:
        raise ValueError("x and y differ in length")
    if direction is None:
        groups = [np.ones(x.size, dtype=bool)]
    else:
        direction = np.asarray(direction).ravel()
        groups = [direction == v for v in np.unique(direction)]
    total, count = 0.0, 0
    for g in groups:
        s, n = _gsj_sum(x[g], y[g])
        total += s
        count += n
    if count == 0:
        raise ValueError("need at least 3 points (per direction) to estimate noise")
    return float(np.sqrt(total / count))


def estimate_hysteresis(x, y, direction):
    """Half the mean reference gap between the +1 and -1 runs at equal x (0 without both runs).

    Each -1 sample is compared with the +1 run interpolated at its x (the runs are dense, so
    interpolation error is far below the noise, which averages out over the run).
    """
    if direction is None:
        return 0.0
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    d = np.asarray(direction)
    fwd, back = d == 1, d == -1
    if np.count_nonzero(fwd) < 3 or np.count_nonzero(back) < 3:
        return 0.0
    xf, inverse = np.unique(x[fwd], return_inverse=True)
    yf = np.bincount(inverse, weights=y[fwd]) / np.bincount(inverse)
    inside = back & (x >= xf[0]) & (x <= xf[-1])
    if not inside.any():
        return 0.0
    return float(np.mean(np.interp(x[inside], xf, yf) - y[inside]) / 2)


def curve_floor(x, y, direction=None):
    """The lowest RMS one curve of x alone can reach: noise plus hysteresis it cannot follow."""
    noise = estimate_noise(x, y, direction)
    h = estimate_hysteresis(x, y, direction)
    return float(np.hypot(noise, h))
