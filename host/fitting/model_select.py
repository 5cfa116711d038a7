"""`--model auto`: choose the calibration curve, among those the firmware can run, that predicts
positions it was not fitted to best.

The firmware evaluates two kinds of pot curve in integer arithmetic: the rational Bezier of
degree 3 (`bcm3`; degrees 1 and 2 are the same curves after exact degree elevation) and a
piecewise-linear table (`pwl`). The candidates are BCM of degree 1..3 and free-knot tables of
TABLE_KNOTS knots, within a budget of stored numbers (n_params).

Rule: each candidate whose RMS on the sweep is within PRUNE of the best one's is scored by the
root mean square of its hold-out errors over interleaved folds (host/fitting/cross_validation.py:
sample i held out in fold i % 5, so every fold spans the sweep), and the cheapest whose score is
within NEAR_BEST of the lowest is taken. A curve that only learns the sweep's noise scores worse
on the held-out samples; one that cuts a knee scores worse too, however close its RMS is to the
noise floor.

Why not the cheapest curve within 10 % of the noise floor (the rule until stop 58): the
deformation the force estimate rests on is the difference of two pots' positions less a few
hundred um, so a curve that is 10-40 um off over a millimetre or two (at a knee, on a pot whose
sweep is noisy, where a few more knots would follow it) costs 0.1-0.6 N at 15 N/mm, and the RMS
cannot see it: 10 um of local error under 20-30 um of noise moves the RMS by a few per cent. On
the 24 pots of stop 55's fresh run (development data, against the simulator's noise-free curves,
what is left after a 5 mm running mean: what neither Df nor the deformation tables take out)
the old rule's curves were 0.3-10 um rms off, 2-83 um at worst; cross-validated ones 0.2-5 um,
1-40 um (docs/robustness.md, stop 58).

`bias_z` (the largest bin's mean residual in standard errors, against what noise reaches) is kept
in `tried` and in the reason: a chosen curve with a local bias beyond the noise says so.
"""

import math
from dataclasses import dataclass, field

import numpy as np

from host.fitting.cross_validation import cv_rms
from host.fitting.models import fit_model

BCM_DEGREES = (1, 2, 3)  # what firmware/bcm_fixed.bcm3 can evaluate (after degree elevation)
TABLE_KNOTS = (2, 3, 5, 9, 13, 17, 21, 25, 29, 33)  # the tables tried; the firmware takes any length
DEFAULT_BUDGET = 64  # numbers a pot curve may store: a table of up to 33 knots
NEAR_BEST = 1.005  # a candidate this close to the lowest cross-validated error is as good
PRUNE = 1.10  # candidates whose RMS on the sweep is further above the best one's are not cross-validated
BIAS_BINS = 60  # about 1 mm each over a 60 mm stroke
BIAS_ALPHA = 0.03  # chance that pure noise fails the bias check somewhere in its BIAS_BINS bins
BIAS_MIN_SAMPLES = 10  # bins with fewer samples are not judged


@dataclass
class Selection:
    result: object  # the chosen FitResult
    reason: str  # one sentence a person can read
    tried: list = field(default_factory=list)  # dicts: model, order, n_params, rms, cv_rms (None: not scored), bias_z


def candidates(budget=DEFAULT_BUDGET):
    """(n_params, model, order) the firmware can evaluate, cheapest first, within the budget."""
    out = [(2 * n + 1, "bcm", n) for n in BCM_DEGREES]
    out += [(2 * k - 2, "pwl", k) for k in TABLE_KNOTS]  # a table stores interior knot positions and every knot value
    return sorted((c for c in out if c[0] <= budget), key=lambda c: (c[0], c[1] != "bcm"))


def bias_z(result, x, y, bins=BIAS_BINS):
    """The largest |mean residual| of a bin of codes, in standard errors of that bin's mean (from
    the bin's own scatter: near a pot's flat end one code spans several times more travel, so
    the noise in mm is larger there than the sweep's floor says), as a fraction of the Student-t
    quantile the noise alone reaches at BIAS_ALPHA over all bins: above 1, a local bias."""
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


def select_model(x, y, noise=None, budget=DEFAULT_BUDGET, n_excluded=0, progress=None):
    """Fit the candidates, cross-validate the close ones; returns a Selection (see the module
    docstring for the rule). `noise` (the sweep's floor, when known) only enters the reason."""
    cands = candidates(budget)
    if not cands:
        raise ValueError("no firmware model fits within a budget of %d parameters" % budget)
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    tried, fits = [], []
    for n_params, model, order in cands:
        if progress:
            progress("auto: fitting %s order %d (%d parameters)" % (model, order, n_params))
        r = fit_model(model, x, y, order, n_excluded=n_excluded)
        fits.append(r)
        tried.append({"model": model, "order": order, "n_params": r.n_params, "rms": r.rms, "cv_rms": None,
                      "bias_z": bias_z(r, x, y) if math.isfinite(r.rms) else None})
    usable = [i for i, r in enumerate(fits) if r.monotone and math.isfinite(r.rms)] or list(range(len(fits)))
    best_rms = min(fits[i].rms for i in usable)
    for i in usable:
        if fits[i].rms <= PRUNE * best_rms:
            t = tried[i]
            if progress:
                progress("auto: cross-validating %s order %d" % (t["model"], t["order"]))
            try:
                t["cv_rms"] = cv_rms(len(x), lambda train, t=t: fit_model(t["model"], x[train], y[train], t["order"]),
                                     lambda f, test: y[test] - f(x[test]))
            except ValueError:  # a fold too thin for this many knots: not scored
                pass
    scored = [i for i in usable if tried[i]["cv_rms"] is not None and math.isfinite(tried[i]["cv_rms"])]
    if not scored:  # too few samples to hold any out: the most accurate on the sweep
        i = min(usable, key=lambda j: fits[j].rms)
        return Selection(fits[i], "%s order %d: the most accurate on the sweep (none could be cross-validated)"
                         % (tried[i]["model"], tried[i]["order"]), tried)
    lowest = min(tried[i]["cv_rms"] for i in scored)
    i = min((j for j in scored if tried[j]["cv_rms"] <= NEAR_BEST * lowest), key=lambda j: cands[j][0])
    t = tried[i]
    reason = ("%s order %d (%d parameters) is the cheapest firmware model within %.1f %% of the lowest cross-validated "
              "error (%.4g against %.4g; rms %.4g%s)" % (
                  t["model"], t["order"], t["n_params"], 100 * (NEAR_BEST - 1), t["cv_rms"], lowest, t["rms"],
                  "" if not noise else ", %.2fx the sweep's noise floor" % (t["rms"] / noise)))
    if (t["bias_z"] or 0.0) > 1.0:
        reason += "; it keeps a local bias beyond the noise (largest 1/%d-range bin mean %.1fx what noise reaches)" % (
            BIAS_BINS, t["bias_z"])
    return Selection(fits[i], reason, tried)
