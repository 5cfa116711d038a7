"""The friction trim: the block's friction h as the running force loop meets it, after the force step.

The force step identifies F0(d) and h from open-loop duty levels: the motor stalls against the
fibre, the spring stands still, and the block comes to rest with its friction against it. Force
mode is different: the loop answers the pots' noise by moving the spring, and the block, which
follows the spring's extremes, slides on a little past where a still spring would leave it. The
friction the estimate should subtract is then not quite the one the open-loop levels measured.
On nine simulated actuators (docs/robustness.md) it was 70 mN lower on one, 50 mN higher on
another: 1-1.5 % of a 5 N step, on a 2 % target.

So once the force calibration is on the board, force mode holds a few targets on each gauge side,
loading then unloading, and compares its estimate with the gauge. A friction term that is too
large leaves the estimate low while loading and high while unloading (F = F0(d) + h s, s the
side the block last slid to), and an error in F0 is the same in both, so

    h_trimmed = h + (mean(estimate - gauge | loading) - mean(estimate - gauge | unloading)) / 2

in force magnitudes. The holds also serve host/experiments/force_runs.py (hold_sequence).
"""

from dataclasses import dataclass

from host.guided import acquire
from host.guided.force_calibration import SIDES, TAUT_N, GaugeOnSide
from host.guided.prompts import end_progress, progress_line

PRELOAD_N = 0.5  # takes up the fibre's slack before the first target
TRIM_FRACTIONS = (0.25, 0.5, 0.75, 0.5, 0.25)  # of a side's identified force range: loading, then unloading
TRIM_SETTLE_S, TRIM_MEASURE_S = 1.5, 0.5  # as the paper's force steps hold each target
TRIM_LIMIT = (0.5, 0.2)  # a trim that moves h by more than this fraction of it and more than this many N is not trusted


def _hold(client, gauge, target_n, settle_s, measure_s):
    """Force mode at `target_n`: settle, log, record the gauge; the firmware's mean estimate."""
    client.call("target", int(round(target_n * 1000)))
    acquire.collect(client, settle_s)
    rec = acquire.collect(client, measure_s)
    gauge.record(rec)
    return acquire.mean(rec, "force_mN") / 1000.0


def hold_sequence(session, rig, prompter, anchor_mm, side, targets, settle_s, measure_s, label, preload=False):
    """Force targets in turn against the gauge on `side`, hooked with the fibre just slack (0.2 mm)
    and tared before and after (the zero drifts): (targets, gauge forces, firmware estimates).
    With `preload`, a PRELOAD_N hold first takes up the fibre's slack, as on a bench before a
    measurement: the first step then starts from a taut fibre, not from a block that hits it."""
    client = session.client
    gauge = GaugeOnSide(session, rig, prompter, anchor_mm, side, gap_mm=0.2)
    gauge.tare()
    acquire.reset(client)
    client.call("mode", "force")
    if preload:
        client.call("target", int(SIDES[side] * PRELOAD_N * 1000))
        acquire.collect(client, 0.5)
    estimates = []
    for target in targets:
        estimates.append(_hold(client, gauge, target, settle_s, measure_s))
        progress_line("  %s: target %+.1f N, estimate %+.2f N" % (label, target, estimates[-1]))
    end_progress()
    gauge.tare(move=True)
    client.call("stop")
    return targets, gauge.forces(), estimates


def trim_magnitudes(range_n):
    """The trim's target magnitudes (N) on a side whose force identification reached `range_n`."""
    return [round(f * range_n, 1) for f in TRIM_FRACTIONS]


@dataclass
class Trim:
    friction_n: float  # the trimmed h (the identified one when `why` says it was not trimmed)
    loading_mn: float  # mean estimate - gauge while loading, mN (force magnitudes)
    unloading_mn: float  # ... while unloading
    holds: int  # holds used (taut fibre)
    why: str = ""  # why h was kept, else empty


def trimmed_friction(friction_n, sides):
    """The Trim of h (N) from the holds of each side, `sides`: per side, rows (target magnitude N,
    estimate magnitude N, gauge magnitude N) in the order held after the preload. A hold loads
    when its target is above the one before. Holds with a slack fibre say nothing: left out."""
    up, down = [], []
    for rows in sides:
        previous = PRELOAD_N
        for target, estimate, gauge in rows:
            if gauge > TAUT_N:
                (up if target > previous else down).append(1000.0 * (estimate - gauge))
            previous = target
    n = len(up) + len(down)
    if not up or not down:
        return Trim(friction_n, float("nan"), float("nan"), n, "no loading or no unloading hold with a taut fibre")
    mu, md = sum(up) / len(up), sum(down) / len(down)
    trimmed = friction_n + (mu - md) / 2000.0
    if abs(trimmed - friction_n) > max(TRIM_LIMIT[0] * friction_n, TRIM_LIMIT[1]):
        return Trim(friction_n, mu, md, n, "the trim would move h by %+.0f mN, more than %d %% of it and %.0f mN" % (
            trimmed * 1000 - friction_n * 1000, 100 * TRIM_LIMIT[0], 1000 * TRIM_LIMIT[1]))
    return Trim(max(0.0, trimmed), mu, md, n)


def trim_friction(session, rig, prompter, opts, data):
    """Force-mode holds on each side the force step used (`data`: its StepOutcome.data), with the
    force calibration on the board: the Trim of its friction h."""
    sides = []
    for side in data["sides"]:
        sign = SIDES[side]
        reached = max([sign * f for f in data["force_n"] if sign * f > 0] or [0.0])
        magnitudes = trim_magnitudes(reached)
        if not magnitudes or magnitudes[0] <= 2 * TAUT_N:
            continue
        _, measured, estimates = hold_sequence(session, rig, prompter, opts.anchor_mm, side,
                                               [sign * m for m in magnitudes], TRIM_SETTLE_S, TRIM_MEASURE_S,
                                               "friction trim, %s side" % side, preload=True)
        sides.append([(m, sign * e, sign * float(g)) for m, e, g in zip(magnitudes, estimates, measured)])
    rig.no_load()
    return trimmed_friction(data["friction_n"], sides)
