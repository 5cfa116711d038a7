"""The result object every calibration model returns (SciPy-style: named fields, no tuples).

A `FitResult` maps a potentiometer reading x (ADC code, volts, any unit) to a position y (the
sweep's reference unit, mm for our pots). It can evaluate itself, invert itself (for monotone
curves) and describe itself as a plain dict for `--json` and the calibration file.
"""

import math
from dataclasses import dataclass, field

import numpy as np


@dataclass
class FitResult:
    model: str  # registry name: "bcm", "pcm", "pcm-raw", "cheb", "spline", "pchip", "lut", "pwl"
    order: int  # degree for bcm/pcm/cheb; number of points or knots for lut/pwl/spline/pchip
    n_params: int  # free numbers the model stores (what a firmware would have to keep)
    coefficients: dict  # model-specific, JSON-serialisable (lists and floats only)
    x_range: tuple  # (lo, hi) of the inputs the fit is valid for
    curve: object = field(repr=False)  # callable: array of x -> array of y
    rms: float = float("nan")
    max_abs: float = float("nan")
    monotone: bool = False
    n_samples: int = 0
    n_excluded: int = 0
    fit_seconds: float = 0.0
    notes: list = field(default_factory=list)  # what the fitter did that a user should know

    def __call__(self, x):
        return self.curve(np.asarray(x, dtype=float))

    def inverse(self, y, tol=1e-9):
        """x such that f(x) = y, for a monotone fit (bisection on a dense bracket)."""
        if not self.monotone:
            raise ValueError("only a monotone calibration can be inverted")
        lo, hi = self.x_range
        grid = np.linspace(lo, hi, 4097)
        fg = self(grid)
        increasing = fg[-1] >= fg[0]
        y = np.atleast_1d(np.asarray(y, dtype=float))
        # bracket each y between two grid points (the grid values are sorted: the curve is monotone),
        # then bisect; a y beyond the curve's range ends at the nearer end of the input range
        idx = np.clip(np.searchsorted(fg if increasing else -fg, y if increasing else -y), 1, len(grid) - 1)
        a, b = grid[idx - 1].copy(), grid[idx].copy()
        for _ in range(60):
            mid = 0.5 * (a + b)
            below = (self(mid) < y) if increasing else (self(mid) > y)
            a = np.where(below, mid, a)
            b = np.where(below, b, mid)
            if np.max(b - a) <= tol * max(1.0, abs(hi - lo)):
                break
        out = 0.5 * (a + b)
        return out if out.size > 1 else float(out[0])

    def summary(self):
        """The fields `host fit --json` prints (plus coefficients)."""
        return {
            "model": self.model,
            "order": int(self.order),
            "n_params": int(self.n_params),
            "rms": float(self.rms),
            "max_abs": float(self.max_abs),
            "monotone": bool(self.monotone),
            "n_samples": int(self.n_samples),
            "n_excluded": int(self.n_excluded),
            "fit_seconds": float(self.fit_seconds),
            "x_range": [float(self.x_range[0]), float(self.x_range[1])],
            "coefficients": self.coefficients,
            "notes": list(self.notes),
        }


def residual_stats(result, x, y):
    """Fill rms and max_abs of `result` from data (x, y); returns the residuals y - f(x)."""
    r = np.asarray(y, dtype=float) - result(x)
    result.rms = float(np.sqrt(np.mean(r * r)))
    result.max_abs = float(np.max(np.abs(r)))
    return r


def check_points(x):
    """Every input a curve fitted to inputs x can meet: each integer code when x holds ADC codes
    (up to 2**17 of them, so 16-bit converters too), else a dense grid of 4,097 points."""
    lo, hi = float(np.min(x)), float(np.max(x))
    if np.all(np.asarray(x) == np.round(x)) and hi - lo <= 1 << 17:
        return np.arange(math.ceil(lo), math.floor(hi) + 1, dtype=float)
    return np.linspace(lo, hi, 4097)


def is_monotone(result, x=None):
    """True when the curve never reverses direction over its inputs: every code when `x` (the
    data it was fitted to) holds ADC codes, else a dense grid of its input range."""
    points = np.linspace(*result.x_range, 4097) if x is None else check_points(x)
    f = result(points)
    d = np.diff(f)
    span = abs(f[-1] - f[0]) or 1.0
    eps = 1e-12 * span
    return bool(np.all(d >= -eps) or np.all(d <= eps))
