"""Choosing a polynomial's order by cross-validation, for the Df and the force fits.

A higher order always fits the samples better; what it must do to be chosen is predict samples
it was not fitted to. Each order is scored by the root mean square of its hold-out errors over
interleaved folds (sample i is held out in fold i % folds, so every fold spans the whole range),
and the lowest order within 5 % of the best score is taken: the simplest curve the data cannot
tell from the best one.
"""

import numpy as np

FOLDS = 5
NEAR_BEST = 1.05


def cv_rms(n, fit, residuals, folds=FOLDS):
    """Root mean square hold-out error over `folds` interleaved folds of `n` samples.

    fit(train) -> a model from the samples where the boolean mask `train` is set;
    residuals(model, test) -> the model's errors on the samples where `test` is set."""
    idx = np.arange(n)
    err = []
    for k in range(folds):
        test = idx % folds == k
        err.append(residuals(fit(~test), test))
    return float(np.sqrt(np.mean(np.concatenate(err) ** 2)))


def lowest_near_best(scores, floor=1):
    """The lowest order >= `floor` whose score ({order: cv rms}) is within NEAR_BEST of the best
    score among the orders >= `floor`."""
    best = min(s for n, s in scores.items() if n >= floor)
    return min(n for n, s in scores.items() if n >= floor and s <= NEAR_BEST * best)
