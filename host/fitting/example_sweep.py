"""A realistic simulated calibration sweep of a 60 mm linear pot with two knee points.

`python -m host.fitting.example_sweep [PATH]` regenerates examples/sweep_60mm.csv (deterministic, seed 7).
The physical model is described in examples/README.md; in short:

- the wiper position s (mm, 0..60) maps to a fraction of the supply through a resistive track
  whose end zones (terminations, below ~4.8 mm and above ~55.8 mm) have less resistance per mm
  than the middle: three straight pieces joined by smooth knees (softplus blends);
- the track slightly overshoots the ADC range at both ends, so a few readings clip at 0 and 4095;
- a 12-bit ADC reads it with Gaussian noise of 1.5 LSB, rounded to whole codes;
- the carriage moves forward then back; the pot's coupling has 50 um of backlash (the pot lags
  by that much in the direction of motion), the reference scale reads to 1 um.
"""

import sys
from pathlib import Path

import numpy as np

STROKE_MM = 60.0
ADC_MAX = 4095
NOISE_LSB = 1.5
BACKLASH_MM = 0.05
KNEES_MM = (4.8, 55.8)
SLOPES = (0.45, 1.0, 0.5)  # resistance per mm of the lower end zone, middle and upper end zone
KNEE_WIDTH_MM = 1.2
UNDERSHOOT, OVERSHOOT = -0.0018, 1.0015  # track fraction at s = 0 and s = 60 (beyond the rails)
SEED = 7
PER_DIRECTION = 900
DEFAULT_PATH = Path(__file__).resolve().parents[2] / "examples" / "sweep_60mm.csv"


def _softplus(z, width):
    return width * np.logaddexp(0.0, z / width)


def _track(s):
    """Unscaled track resistance from 0 to s: three slopes joined by smooth knees."""
    s = np.asarray(s, dtype=float)
    a, b, c = SLOPES
    k1, k2 = KNEES_MM
    return a * s + (b - a) * _softplus(s - k1, KNEE_WIDTH_MM / 4) + (c - b) * _softplus(s - k2, KNEE_WIDTH_MM / 4)


def true_fraction(s_mm):
    """Wiper voltage as a fraction of the ADC full scale at position s (may leave [0, 1])."""
    r0, r1 = _track(0.0), _track(STROKE_MM)
    u = (_track(s_mm) - r0) / (r1 - r0)
    return UNDERSHOOT + (OVERSHOOT - UNDERSHOOT) * u


def simulate_sweep(seed=SEED, per_direction=PER_DIRECTION, noise_lsb=NOISE_LSB, backlash_mm=BACKLASH_MM):
    """(t_s, raw, reference_mm, direction) arrays of one forward-and-back sweep."""
    rng = np.random.default_rng(seed)
    # positions visited at a steady speed with a little jitter in where each sample lands
    fwd = np.linspace(0.0, STROKE_MM, per_direction) + rng.normal(0, 0.01, per_direction)
    back = np.linspace(STROKE_MM, 0.0, per_direction) + rng.normal(0, 0.01, per_direction)
    s = np.clip(np.concatenate([fwd, back]), 0.0, STROKE_MM)
    direction = np.concatenate([np.ones(per_direction), -np.ones(per_direction)])
    wiper = s - direction * backlash_mm / 2  # the pot lags half the play behind in each direction
    code = true_fraction(wiper) * ADC_MAX + rng.normal(0, noise_lsb, s.size)
    raw = np.clip(np.round(code), 0, ADC_MAX).astype(int)
    reference = np.round(s, 3)
    t_s = np.arange(s.size) * 0.01
    return t_s, raw, reference, direction.astype(int)


def write_sweep(path=DEFAULT_PATH, seed=SEED):
    t_s, raw, ref, direction = simulate_sweep(seed)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w") as fh:
        fh.write("t_s,raw,reference,direction\n")
        for row in zip(t_s, raw, ref, direction):
            fh.write("%.2f,%d,%.3f,%d\n" % row)
    return path


if __name__ == "__main__":
    out = write_sweep(sys.argv[1] if len(sys.argv) > 1 else DEFAULT_PATH)
    print("wrote %s" % out)
