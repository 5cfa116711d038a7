"""`--model auto`: choose the cheapest calibration the firmware can run that is good enough.

The firmware evaluates two kinds of pot curve in integer arithmetic: the rational Bezier of
degree 3 (`bcm3`; degrees 1 and 2 are the same curves after exact degree elevation) and a
piecewise-linear table (`pwl`). The candidates are therefore BCM of degree 1..3 and free-knot
piecewise-linear curves with k knots, ordered by how many numbers the fit stores (n_params).

Rule: take the cheapest candidate whose RMS is within `tolerance` (10 %) of the sweep's noise
floor, because a better fit than the noise allows only learns the noise. If none gets there,
take the most accurate candidate within the parameter budget (default 12 numbers), and say so.
"""

from dataclasses import dataclass, field

from host.fitting.models import fit_model

BCM_DEGREES = (1, 2, 3)  # what firmware/bcm_fixed.bcm3 can evaluate (after degree elevation)
DEFAULT_BUDGET = 12
DEFAULT_TOLERANCE = 0.10


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
        tried.append({"model": model, "order": order, "n_params": r.n_params, "rms": r.rms})
        if target is not None and r.rms <= target and r.monotone:
            reason = (
                "%s order %d is the cheapest firmware model (%d parameters) within %.0f %% of the floor "
                "(rms %.4g vs floor %.4g)" % (model, order, r.n_params, 100 * tolerance, r.rms, noise)
            )
            return Selection(r, reason, tried)
    usable = [r for r in fits if r.monotone] or fits
    best = min(usable, key=lambda r: r.rms)
    if target is None:
        why = "the noise floor is unknown"
    else:
        why = "no model within %d parameters got within %.0f %% of the floor %.4g" % (budget, 100 * tolerance, noise)
    reason = "%s, so the most accurate one was chosen: %s order %d (%d parameters, rms %.4g%s)" % (
        why,
        best.model,
        best.order,
        best.n_params,
        best.rms,
        "" if not noise else ", %.2fx the floor" % (best.rms / noise),
    )
    return Selection(best, reason, tried)
