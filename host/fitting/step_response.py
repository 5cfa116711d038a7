"""Figures of a closed loop's step response: rise time, overshoot, settling time, steady-state
error, and whether the loop oscillates (a limit cycle) rather than settling.

`analyse(t, y, start, target, band)` takes the response sampled at times `t` (seconds from the
step) and returns a `StepResponse` with named fields. Definitions, for a step of size
S = target - start and the normalised response s = (y - start) / S:
- rise time: from s first reaching 0.1 to s first reaching 0.9 (None when it never gets there);
- overshoot: max(s) - 1, as a fraction of the step (0 when it never passes the target);
- settling time: from the step to the last sample outside target +- band, when every later
  sample is inside (None when the response is still outside the band at the end of the record,
  or oscillates);
- steady-state error: the mean of the last fifth of the record minus the target;
- oscillating: over the second half of the record, the response smoothed over `smooth` samples
  swings by more than 2 band peak to peak and crosses its own mean at least 4 times. A slow
  creep is "not settled", a limit cycle is "oscillating"; sensor noise (smoothed away) is neither.
"""

import numpy as np


class StepResponse:
    """The figures of one step response (units of y, seconds)."""

    def __init__(self, t, y, start, target, band, rise_s, overshoot, settling_s, steady_error, oscillating, swing):
        self.t = t
        self.y = y
        self.start = start
        self.target = target
        self.band = band
        self.rise_s = rise_s
        self.overshoot = overshoot
        self.settling_s = settling_s
        self.steady_error = steady_error
        self.oscillating = oscillating
        self.swing = swing  # peak-to-peak of the smoothed response over the second half

    @property
    def settled(self):
        return self.settling_s is not None and not self.oscillating

    def verdict(self):
        if self.oscillating:
            return "oscillates"
        return "settles" if self.settled else "does not settle"

    def as_dict(self):
        return {"start": self.start, "target": self.target, "band": self.band, "rise_s": self.rise_s,
                "overshoot": self.overshoot, "settling_s": self.settling_s, "steady_error": self.steady_error,
                "oscillating": self.oscillating, "swing": self.swing, "verdict": self.verdict()}


def _first(mask):
    idx = np.flatnonzero(mask)
    return int(idx[0]) if len(idx) else None


def analyse(t, y, start, target, band, smooth=10):
    t = np.asarray(t, dtype=float)
    y = np.asarray(y, dtype=float)
    if len(t) < 10 or len(t) != len(y):
        raise ValueError("a step response needs at least 10 samples of time and value")
    step = float(target) - float(start)
    if step == 0:
        raise ValueError("the step must change the target")
    s = (y - start) / step
    i10, i90 = _first(s >= 0.1), _first(s >= 0.9)
    rise = float(t[i90] - t[i10]) if i10 is not None and i90 is not None else None
    overshoot = max(0.0, float(np.max(s)) - 1.0)
    outside = np.flatnonzero(np.abs(y - target) > band)
    if len(outside) == 0:
        settling = 0.0
    elif outside[-1] == len(y) - 1:
        settling = None
    else:
        settling = float(t[outside[-1] + 1])
    steady = float(np.mean(y[-max(1, len(y) // 5):]) - target)
    half = y[len(y) // 2:]
    k = max(1, min(int(smooth), len(half) // 4))
    smoothed = np.convolve(half, np.ones(k) / k, mode="valid")
    swing = float(np.ptp(smoothed)) if len(smoothed) else 0.0
    centred = smoothed - np.mean(smoothed)
    crossings = int(np.count_nonzero(np.diff(np.sign(centred[centred != 0])) != 0))
    oscillating = swing > 2 * band and crossings >= 4
    if oscillating:
        settling = None  # a limit cycle passing through the band at the end has not settled
    return StepResponse(t, y, float(start), float(target), float(band), rise, overshoot, settling, steady, oscillating, swing)


def best(results):
    """Index of the best of (label, StepResponse) pairs: settled and not oscillating, overshoot
    at most 20 %, then the shortest settling time (ties: less overshoot); None when none qualifies."""
    ok = [(r.settling_s, r.overshoot, i) for i, (_, r) in enumerate(results) if r.settled and r.overshoot <= 0.2]
    return min(ok)[2] if ok else None
