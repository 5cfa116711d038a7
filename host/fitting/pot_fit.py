"""One pot's calibration curve from its sweep: the model and order, the sweep's noise floors, and
whether the fit may be written as a calibration.

`fit_sweep` is what `host fit`, `host demo` and the guided pots step run: a named model at an
order (DEFAULT_ORDER when none is given), or `auto`, the cheapest curve the firmware evaluates
that predicts held-out samples as well as the best one (host/fitting/model_select.py). `refusals` says why a fit
must not become a calibration (a reference that is not a function of the reading, a curve that
is not monotone).
"""

import math

from host.errors import UserError

DEFAULT_ORDER = {"bcm": 3, "pcm": 10, "pcm-raw": 10, "cheb": 10, "spline": 8, "pchip": 8, "lut": 16, "pwl": 5}
MAX_ORDER = 40

RMS_WARN = 10  # rms / noise floor: a poor fit (a quadratic on a knee-shaped pot is ~17)
RMS_REFUSE = 50  # ... and a sweep that is not a calibration (a reference that is not a function of the reading)
SPAN_REFUSE = 0.02  # rms over 2 % of the reference's span (1.2 mm on a 60 mm pot; BCM-3 leaves ~0.2 %)


def fit_sweep(sweep, model="bcm", order=None, bounds="data", budget=12, progress=None):
    """(FitResult, floors dict, auto reason or None) for a loaded Sweep.

    floors: noise_floor (the scatter, by direction), hysteresis (half the gap between directions)
    and curve_floor (what one curve of raw alone can reach: both combined), None when unknown.
    """
    from host.fitting.model_select import select_model
    from host.fitting.models import fit_model
    from host.fitting.noise_floor import estimate_hysteresis, estimate_noise

    try:
        noise = estimate_noise(sweep.x, sweep.y, sweep.direction)
        hyst = estimate_hysteresis(sweep.x, sweep.y, sweep.direction)
        floors = {"noise_floor": noise, "hysteresis": hyst, "curve_floor": float((noise**2 + hyst**2) ** 0.5)}
    except ValueError:
        floors = {"noise_floor": None, "hysteresis": None, "curve_floor": None}
    if model == "auto":
        sel = select_model(sweep.x, sweep.y, floors["curve_floor"], budget=budget, n_excluded=sweep.n_excluded,
                           progress=progress)
        return sel.result, floors, sel.reason
    order = DEFAULT_ORDER[model] if order is None else order
    if not 1 <= order <= MAX_ORDER:
        raise UserError("the order of a %s curve must be between 1 and %d, not %d" % (model, MAX_ORDER, order))
    options = {"bounds": bounds} if model == "bcm" else {}
    if progress:
        progress("fitting %s order %d to %d samples" % (model, order, sweep.x.size))
    try:
        result = fit_model(model, sweep.x, sweep.y, order, n_excluded=sweep.n_excluded, **options)
    except ValueError as exc:
        raise UserError("%s order %d cannot be fitted to this sweep: %s" % (model, order, exc)) from None
    return result, floors, None


def refusals(result, noise, span):
    """Why a fit must not be written as a calibration (empty when it may)."""
    why = []
    if not (math.isfinite(result.rms) and math.isfinite(result.max_abs)):
        why.append("its error is not finite (rms %s): the sweep's numbers are out of range" % result.rms)
    elif span and result.rms > SPAN_REFUSE * span:
        why.append("its rms %.4g is %.1f %% of the reference's span %.4g (limit %.0f %%): is the reference a function "
                   "of the reading?" % (result.rms, 100 * result.rms / span, span, 100 * SPAN_REFUSE))
    elif noise and result.rms > RMS_REFUSE * noise:
        why.append("its rms %.4g is %.0f times the sweep's noise floor %.4g (limit %d): is the reference a function "
                   "of the reading?" % (result.rms, result.rms / noise, noise, RMS_REFUSE))
    if not result.monotone:
        why.append("the curve is not monotone, so the firmware could not tell positions apart")
    elif float(result(result.x_range[1])) < float(result(result.x_range[0])):
        why.append("the position falls as the reading rises, and the firmware refuses such a curve (positions must "
                   "grow toward 60 mm): add this pot to \"pot_invert\" in the board file (host calibrate bringup "
                   "finds it) and sweep again")
    return why


def poor_fit(result, noise):
    """True when the fit may be written but is poor: between RMS_WARN and RMS_REFUSE times the noise floor."""
    return bool(noise) and RMS_WARN * noise < result.rms <= RMS_REFUSE * noise
