"""The registry of calibration models: one name, one fitting function, one interface.

Every fitter has the signature `fit_xxx(x, y, order, **options) -> FitResult` where x and y are
float arrays sorted by x (a cleaned sweep). `fit_model` times the fit alone and fills the
statistics every model shares, so the numbers are comparable across models.
"""

import importlib
import time

from host.fitting.fit_result import is_monotone, residual_stats

# name -> (module, function, what it is)
MODELS = {
    "bcm": ("host.fitting.rational_bezier", "fit_bcm", "rational Bernstein (Bezier) curve of degree n, the paper's BCM"),
    "pcm": ("host.fitting.polynomial", "fit_pcm", "polynomial of order n on x scaled to [0, 1]"),
    "pcm-raw": ("host.fitting.polynomial", "fit_pcm_raw", "polynomial of order n on raw x, as the paper's polyfit"),
    "cheb": ("host.fitting.polynomial", "fit_chebyshev", "Chebyshev series of order n"),
    "spline": ("host.fitting.spline", "fit_spline", "cubic spline with n knots"),
    "pchip": ("host.fitting.spline", "fit_pchip", "monotone cubic (PCHIP) with n knots"),
    "lut": ("host.fitting.piecewise_linear", "fit_lut", "piecewise-linear table with n evenly spaced points"),
    "pwl": ("host.fitting.piecewise_linear", "fit_pwl", "piecewise-linear with n free knots"),
}


def fitter(name):
    try:
        module, func, _ = MODELS[name]
    except KeyError:
        raise ValueError("unknown model %r (choose from %s)" % (name, ", ".join(MODELS))) from None
    return getattr(importlib.import_module(module), func)


def fit_model(name, x, y, order, n_excluded=0, **options):
    """Fit model `name` of size `order` to sorted (x, y); returns a FitResult with statistics."""
    fit = fitter(name)
    t0 = time.perf_counter()
    result = fit(x, y, order, **options)
    result.fit_seconds = time.perf_counter() - t0
    residual_stats(result, x, y)
    result.monotone = is_monotone(result, x)  # every code when x are ADC codes
    result.n_samples = len(x)
    result.n_excluded = n_excluded
    return result
