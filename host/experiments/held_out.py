"""Figures on data the calibration never saw: a Df validation sweep, positions and forces drawn fresh
for each run. The project's targets are judged on these.

The paper's own experiments say how well the calibration fits what it was made from: its Df is the
fit's residual on the sweep it was fitted to, and its force steps (5/10/15 N) sit next to where the
force step's closed-loop trim held the loop against the gauge (host/guided/friction_trim.py:
30/60/90 % of each side's identified range, 4.8/9.6/14.4 N at 16 N). So, once the calibration is
on the board:

- Df: a second no-load sweep at another duty (other samples, other speeds, later, fresh noise).
  The paper's Df correction leaves D1* - D2, which is, at no load, the Df it did not take out plus
  the deflection the block's friction puts into the spring while it slides, of opposite sign in
  the two directions. The bin means over 1 mm of D1 are taken for each direction apart and the
  two averaged, so the deflection cancels and the assembly error stays; the peak |mean| is the
  held-out Df (end-stop samples left out, as the fit does). The firmware's own deformation, with the
  gain step's offset table taken off too (`defl_um`), is binned the same way and reported beside
  it (peak_deformation_mm): what a force estimate at no load starts from.
- positions: POSITIONS drawn uniformly over the soft stroke limits (one in each sixth of it), each
  at least 1 mm from the paper's targets and from each other, held and measured by the reference as Fig. 7's are.
- forces: on each gauge side, LOADING magnitudes drawn from 15-90 % of the range the force step
  reached there (one in each third of it), then UNLOADING ones below the highest (one in each
  third of what is below it), each at least 0.5 N from every magnitude
  the trim held in closed loop, from the paper's 5/10/15 N and from each other, and 0.25 N from
  every level of the force step (the points F0 was fitted to); run as the paper's steps are
  (hold_sequence, 1.5 s to settle, 0.5 s measured).
- forces at another position: the force step and its trim hold the gauge at one anchor (75 % of the
  stroke), and under load the firmware's deformation is the true one times the slope of pot 2's
  calibrated curve there (the reference reads the wiper, so pot 2's mounting error stays in its
  calibration, and Df takes out only the two pots' difference): F0 holds where it was made. So on
  each side AWAY_LOADING more magnitudes, then AWAY_UNLOADING below the highest, drawn as above,
  are run with the gauge hooked at the stroke's middle, where the paper ran its Table 1
  (away_anchor_mm).

The draws come from a generator seeded by the run (`draw_seed`: from the clock unless given),
printed and kept in results.json, so a run can be repeated with the same targets.
"""

import time

import numpy as np

from host.experiments import displacement, force_runs
from host.fitting.assembly import STOP_ZONE_UM, near_the_stops
from host.guided import acquire, stroke
from host.guided.force_identification import SIDES
from host.guided.friction_trim import CHECK_FRACTIONS, trim_magnitudes

POSITIONS = 6
LOADING = 3
UNLOADING = 3
FORCE_GAP_N = 0.5  # a drawn force stays this far from any force a calibration step held in closed loop
LEVEL_GAP_N = 0.25  # and this far from the force step's open-loop levels (F0's points)
POSITION_GAP_MM = 1.0
RANGE_FRACTIONS = (0.15, 0.9)  # of the side's identified range: inside the calibrated F0 table
MIN_FORCE_N = 2.0  # below this a step is mostly the fibre's slack and the block's friction band (the paper's smallest is 5 N)
AWAY_LOADING = 2  # force steps a side with the gauge away from the calibration's anchor
AWAY_UNLOADING = 1
MIN_AWAY_MM = 5.0  # "another position" is at least this far from the anchor
SWEEP_DUTY_FACTOR = 0.8  # the validation sweep's duty, of the calibration sweep's


def draw_seed():
    """A seed no run before this second drew from."""
    return int(time.time()) & 0x7FFFFFFF


def _draw(rng, lo, hi, n, avoid, gap, tries=2000):
    """`n` values drawn uniformly, one in each of `n` equal stretches of [lo, hi] (so they spread
    over it), each at least `gap` from the others and from every (value, distance) in `avoid` by
    its distance; a stretch with no room gives none."""
    out = []
    width = (hi - lo) / n if n else 0.0
    for k in range(n):
        a = lo + k * width
        for _ in range(tries):
            if width <= 0:
                break
            v = round(float(rng.uniform(a, a + width)), 2)
            if all(abs(v - x) >= d for x, d in avoid) and all(abs(v - o) >= gap for o in out):
                out.append(v)
                break
    return out


def draw_positions(rng, stroke_mm, n=POSITIONS, paper_targets=displacement.TARGETS_MM):
    """`n` positions within the soft limits `stroke_mm` (LIMIT_MARGIN_MM inside), off `paper_targets`."""
    lo, hi = stroke_mm[0] + stroke.LIMIT_MARGIN_MM, stroke_mm[1] - stroke.LIMIT_MARGIN_MM
    return sorted(_draw(rng, lo, hi, n, [(t, POSITION_GAP_MM) for t in paper_targets], POSITION_GAP_MM))


def draw_forces(rng, reached_n, held_n=(), levels_n=(), loading=LOADING, unloading=UNLOADING):
    """Magnitudes on one side whose force step reached `reached_n`: loading ones ascending, then
    unloading ones descending from below the highest; at least FORCE_GAP_N from `held_n` (what the
    trim held in closed loop) and the paper's steps, LEVEL_GAP_N from `levels_n` (the force step's
    open-loop levels, the points F0 was fitted to)."""
    lo = max(MIN_FORCE_N, RANGE_FRACTIONS[0] * reached_n)
    hi = RANGE_FRACTIONS[1] * reached_n
    avoid = [(m, FORCE_GAP_N) for m in list(held_n) + [abs(m) for m in force_runs.STEPS_N]]
    avoid += [(m, LEVEL_GAP_N) for m in levels_n]
    up = sorted(_draw(rng, lo, hi, loading, avoid, FORCE_GAP_N))
    if not up:
        return []
    down = sorted(_draw(rng, lo, up[-1] - FORCE_GAP_N, unloading, avoid + [(u, FORCE_GAP_N) for u in up], FORCE_GAP_N),
                  reverse=True)
    return up + down


def away_anchor_mm(stroke_mm, anchor_mm):
    """Where the force steps away from the calibration's position hook the gauge: the stroke's
    middle (the paper's Table 1 ran there), or a quarter of the stroke toward the far end from an
    anchor set within MIN_AWAY_MM of the middle."""
    mid = stroke.middle(stroke_mm)
    if abs(mid - anchor_mm) >= MIN_AWAY_MM:
        return round(mid, 1)
    quarter = stroke.length(stroke_mm) / 4.0
    return round(anchor_mm - quarter if anchor_mm >= mid else anchor_mm + quarter, 1)


def df_validation(session, rig, duty, say=print):
    """The held-out Df: a no-load sweep at `duty` with the calibration on the board (see above)."""
    rig.no_load()
    say("  validation sweep at no load, duty %d (the calibration's was another)" % duty)
    records, direction = acquire.sweep(session.client, duty, say)
    if len(records) < 50:
        return {"peak_binned_mm": float("nan"), "n_samples": int(len(records)), "duty": duty}
    d1 = records[:, acquire.COL["d1_um"]].astype(float)
    d2 = records[:, acquire.COL["d2_um"]].astype(float)
    keep = ~near_the_stops(d2, STOP_ZONE_UM)
    x, resid, direction = d1[keep] / 1000.0, (d1 - d2)[keep] / 1000.0, direction[keep]
    peak, peak_pooled, deflection = direction_balanced_peak(x, resid, direction)
    # the deformation the firmware reads at no load: D1* - D2 less the gain step's offset table, times its gain
    defl = records[:, acquire.COL["defl_um"]].astype(float)[keep] / 1000.0
    peak_firmware = direction_balanced_peak(x, defl, direction)[0]
    return {"peak_binned_mm": peak, "peak_pooled_mm": peak_pooled, "friction_deflection_mm": deflection,
            "peak_deformation_mm": peak_firmware,
            "peak_single_mm": float(np.max(np.abs(resid))), "rms_mm": float(np.sqrt(np.mean(resid ** 2))),
            "n_samples": int(len(x)), "duty": duty}


def direction_balanced_peak(x, resid, direction, width=1.0, min_count=3):
    """(peak |bin mean| over bins `width` mm wide in D1, with each direction's bin mean taken apart
    and the two averaged; the peak of the bin means of both directions pooled, as the fit's own
    figure is taken; the mean of half the difference between the directions, the friction's
    deflection). Bins where a direction has fewer than `min_count` samples are left out."""
    from host.fitting.assembly import binned_peak, direction_bin_means

    _, forward, backward, _ = direction_bin_means(x, resid, direction, width, min_count)
    if not len(forward):
        return float("nan"), binned_peak(x, resid, width), float("nan")
    balanced = (forward + backward) / 2.0
    deflection = float(np.mean((forward - backward) / 2.0))
    return float(np.max(np.abs(balanced))), binned_peak(x, resid, width), deflection


def positions(session, rig, ref_scale, zero, targets):
    """Fig. 7's measurement at the drawn targets (rows as displacement.run_targets gives them)."""
    return displacement.run_targets(session, rig, ref_scale, zero, targets=targets, label="held-out")


def forces(session, rig, prompter, anchor_mm, side, magnitudes):
    """The force steps at drawn `magnitudes` on `side` (rows as force_runs.force_steps gives them)."""
    rows = force_runs.force_steps(session, rig, prompter, anchor_mm, side, magnitudes=magnitudes)
    for row in rows:
        row["held_out"] = True
    return rows


def side_levels(force_data, side):
    """The force magnitudes the force step measured on `side` (N): F0's points there."""
    sign = SIDES[side]
    return sorted({round(sign * float(f), 2) for f in force_data["force_n"] if sign * f > 0})


def side_ranges(force_data, sides):
    """{side: the force magnitude the force step showed the spring can hold on that side} (N):
    the largest it measured, below any hard contact (friction_trim.side_reach)."""
    from host.guided.friction_trim import side_reach

    return {side: side_reach(force_data, side) for side in sides}


def held_by_calibration(reached_n):
    """The magnitudes the force step's closed-loop trim and its F0 check held on a side that
    reached `reached_n`."""
    return sorted(set(trim_magnitudes(reached_n)) | set(trim_magnitudes(reached_n, CHECK_FRACTIONS)))
