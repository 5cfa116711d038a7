"""`--model auto`: choose the cheapest calibration the firmware can run that is good enough.

The firmware evaluates two kinds of pot curve in integer arithmetic: the rational Bezier of
degree 3 (`bcm3`; degrees 1 and 2 are the same curves after exact degree elevation) and a
piecewise-linear table (`pwl`). The candidates are therefore BCM of degree 1..3 and free-knot
piecewise-linear curves with k knots, ordered by how many numbers the fit stores (n_params).

Rule: take the cheapest candidate whose RMS is within `tolerance` (10 %) of the sweep's noise
floor, because a better fit than the noise allows only learns the noise, and whose residuals
have no local bias the noise cannot explain: over BIAS_BINS equal bins of the codes, each bin's
mean residual, in units of its standard error (the bin's own scatter / sqrt(samples in it)),
stays within the Student-t quantile for that bin's sample count at a family-wise false-alarm
rate of BIAS_ALPHA over all bins (Bonferroni): with 10-30 samples a bin's scatter is itself
uncertain, and a fixed 3.5 refused good curves 8-25 % of the time on pure noise. The RMS alone hides a knee the curve cuts: on a pot with 5 LSB of noise a table 44 um
off over a whole millimetre passed at 3 % above the floor, and that error went on into Df and
the position loop. If none gets there, take the most accurate candidate within the parameter
budget (DEFAULT_BUDGET numbers) or, among those within PLATEAU (2 %) of its RMS and without a local
bias, the cheapest, and say so.
"""

import math
from dataclasses import dataclass, field

from host.fitting.models import fit_model

BCM_DEGREES = (1, 2, 3)  # what firmware/bcm_fixed.bcm3 can evaluate (after degree elevation)
DEFAULT_BUDGET = 32  # numbers a pot curve may store: a table of up to 17 knots, what a knee-shaped pot needs
DEFAULT_TOLERANCE = 0.10
BIAS_BINS = 60  # about 1 mm each over a 60 mm stroke
BIAS_ALPHA = 0.03  # chance that pure noise fails the bias check somewhere in its BIAS_BINS bins
PLATEAU = 0.02  # a candidate this close to the best RMS is as good
BIAS_MIN_SAMPLES = 10  # bins with fewer samples are not judged


@dataclass
class Selection:
    result: object  # the chosen FitResult
    reason: str  # one sentence a person can read
    tried: list = field(default_factory=list)  # dicts: model, order, n_params, rms (in the order fitted)


def candidates(budget=DEFAULT_BUDGET):
    """(n_params, model, order) the firmware can evaluate, cheapest first, within the budget."""
    out = [(2 * n + 1, "bcm", n) for n in BCM_DEGREES]
    k = 2
    while 2 * k - 2 <= budget:  # pwl stores interior knot positions and every knot value
        out.append((2 * k - 2, "pwl", k))
        k += 1
    return sorted((c for c in out if c[0] <= budget), key=lambda c: (c[0], c[1] != "bcm"))


def bias_z(result, x, y, bins=BIAS_BINS):
    """The largest |mean residual| of a bin of codes, in standard errors of that bin's mean (from
    the bin's own scatter: near a pot's flat end one code spans several times more travel, so
    the noise in mm is larger there than the sweep's floor says), as a fraction of the Student-t
    quantile the noise alone reaches at BIAS_ALPHA over all bins: above 1, a local bias."""
    import numpy as np
    from scipy.stats import t

    x = np.asarray(x, dtype=float)
    resid = np.asarray(y, dtype=float) - result(x)
    edges = np.linspace(x.min(), x.max(), bins + 1)
    idx = np.clip(np.digitize(x, edges) - 1, 0, bins - 1)
    count = np.bincount(idx, minlength=bins).astype(float)
    total = np.bincount(idx, weights=resid, minlength=bins)
    squares = np.bincount(idx, weights=resid * resid, minlength=bins)
    ok = count >= BIAS_MIN_SAMPLES
    if not ok.any():
        return 0.0
    n, mean = count[ok], total[ok] / count[ok]
    var = np.maximum(squares[ok] - n * mean * mean, 0.0) / (n - 1)
    se = np.sqrt(var / n)
    se = np.maximum(se, 1e-12 + 1e-9 * np.max(np.abs(resid)))  # a noise-free sweep: any offset counts
    critical = t.ppf(1.0 - BIAS_ALPHA / (2.0 * np.count_nonzero(ok)), n - 1)
    return float(np.max(np.abs(mean) / se / critical))


def select_model(x, y, noise=None, budget=DEFAULT_BUDGET, tolerance=DEFAULT_TOLERANCE, n_excluded=0, progress=None):
    """Fit candidates cheapest first; returns a Selection (see the module docstring for the rule)."""
    cands = candidates(budget)
    if not cands:
        raise ValueError("no firmware model fits within a budget of %d parameters" % budget)
    target = None if not noise else (1.0 + tolerance) * noise
    tried, fits = [], []
    for n_params, model, order in cands:
        if progress:
            progress("auto: trying %s order %d (%d parameters)" % (model, order, n_params))
        r = fit_model(model, x, y, order, n_excluded=n_excluded)
        fits.append(r)
        z = bias_z(r, x, y) if noise and math.isfinite(r.rms) else None
        tried.append({"model": model, "order": order, "n_params": r.n_params, "rms": r.rms, "bias_z": z})
        if target is not None and r.rms <= target and r.monotone and z is not None and z <= 1.0:
            reason = (
                "%s order %d is the cheapest firmware model (%d parameters) within %.0f %% of the floor "
                "(rms %.4g vs floor %.4g) with no local bias beyond the noise (largest 1/%d-range bin mean "
                "%.2f of what noise reaches)" % (model, order, r.n_params, 100 * tolerance, r.rms, noise, BIAS_BINS, z)
            )
            return Selection(r, reason, tried)
    usable = [r for r in fits if r.monotone] or fits
    best = min(usable, key=lambda r: r.rms)
    # where the floor is not reached (it underestimates a sweep whose noise varies along the
    # curve), the cheapest candidate within PLATEAU of the best and without a local bias: the
    # extra knots of the best one only follow noise
    z_of = {id(r): t["bias_z"] for r, t in zip(fits, tried)}
    plateau = [r for r in usable if r.rms <= (1.0 + PLATEAU) * best.rms and (z_of[id(r)] or 0.0) <= 1.0]
    if plateau:
        best = plateau[0]
    if target is None:
        why = "the noise floor is unknown"
    else:
        why = ("no model within %d parameters got within %.0f %% of the floor %.4g without a local bias beyond "
               "the noise" % (budget, 100 * tolerance, noise))
    reason = "%s, so the cheapest within %.0f %% of the most accurate was chosen: %s order %d (%d parameters, rms %.4g%s)" % (
        why,
        100 * PLATEAU,
        best.model,
        best.order,
        best.n_params,
        best.rms,
        "" if not noise else ", %.2fx the floor" % (best.rms / noise),
    )
    if (z_of[id(best)] or 0.0) > 1.0:
        reason += "; it keeps a local bias beyond the noise (largest bin mean %.1fx what noise reaches)" % z_of[id(best)]
    return Selection(best, reason, tried)
