"""Paper Fig. 8 (force control at no load: blocking), the force dead zone and Table 1.

- blocking: from D2 = 30 mm, force mode with a target of +F at no load; the block should run on
  to the end of the stroke. Without the Df correction the firmware's deformation includes Df(D1),
  reaches the target deformation part-way and the block stops ("blocks").
- dead zone: with the gauge hooked (fibre just slack at the anchor), force targets 0..-5 N in
  0.2 N steps; the dead zone is the largest |target| whose measured |force| is below half of it.
Each sequence tares the gauge with the fibre slack before and after, and takes every reading
against the tare interpolated to its time (the gauge's zero drifts). The steps start after a
0.5 N preload has taken up the fibre's slack.
- steps (Table 1): targets -5, -10, -15 N and back through -10, -5 N (loading, then unloading)
  with the gauge on the 60 mm side as in the paper, and +5, +10, +15, +10, +5 N with the gauge on
  the 0 mm side; steady-state error (gauge vs target) and estimation error (firmware's force
  estimate vs gauge), in % of the target/measured force.
"""

import numpy as np

from host.guided import acquire
from host.guided.force_identification import SIDES
from host.guided.friction_trim import hold_sequence

STEPS_N = (5.0, 10.0, 15.0, 10.0, 5.0)  # magnitudes: loading, then unloading


def blocking_run(session, rig, target_n, start_mm=30.0, seconds=4.0):
    """(time s, D2 mm) trajectory and the final D2 of a no-load force run from `start_mm` (the
    middle of the stroke: 30 mm of 0-60)."""
    rig.no_load()
    client = session.client
    acquire.hold(client, "position", int(round(start_mm * 1000)), "d2_um", 200, timeout_s=8.0, measure_s=0.1)
    client.call("mode", "force")
    client.call("target", int(target_n * 1000))
    rec = acquire.collect(client, seconds)
    client.call("stop")
    t = (rec[:, acquire.COL["t_us"]] - rec[0, acquire.COL["t_us"]]) / 1e6 if len(rec) else np.zeros(0)
    d2 = rec[:, acquire.COL["d2_um"]] / 1000.0 if len(rec) else np.zeros(0)
    final = float(np.mean(d2[-20:])) if len(d2) else float("nan")
    return {"t": t, "d2": d2, "final": final, "target_n": target_n, "start_mm": start_mm}


def dead_zone(session, rig, prompter, anchor_mm, step_n=0.2, top_n=5.0, settle_s=0.5):
    held = board_force_range(session.client)  # a board that held less than top_n refuses the rest
    targets = [-float(t) for t in np.arange(0.0, top_n + 1e-9, step_n) if not refused(-float(t), held)]
    targets, measured, estimates = hold_sequence(session, rig, prompter, anchor_mm, "high", targets, settle_s, 0.2, "dead zone")
    rows = [{"target": t, "measured": float(m), "estimate": e} for t, m, e in zip(targets, measured, estimates)]
    dz = max([abs(r["target"]) for r in rows if abs(r["measured"]) < 0.5 * abs(r["target"])] or [0.0])
    return rows, dz


IN_RANGE = 0.9  # a step beyond this share of the force the calibration reached on its side is out of its range


def board_force_range(client):
    """(lowest, highest) N of the force targets the board takes (its calibration's force_range),
    or None when it takes any the protocol allows."""
    held = client.call("status").get("force_range_mN")
    return None if not held else (held[0] / 1000.0, held[1] / 1000.0)


def refused(target_n, held):
    """Whether a board whose force range is `held` (board_force_range) refuses `target_n`."""
    return held is not None and not held[0] <= target_n <= held[1]


def beyond_reach(magnitudes, reached_n):
    """The magnitudes beyond `reached_n`, the force the force step held on their side: the board
    refuses them (the calibration's force_range, firmware/app.py), so they are not run."""
    return list(dict.fromkeys(m for m in magnitudes if reached_n is not None and m > reached_n))


def force_steps(session, rig, prompter, anchor_mm, side="high", magnitudes=STEPS_N, settle_s=1.5, reached_n=None):
    """Rows of one force-step sequence against the gauge on `side` (sign of the targets from it).
    `reached_n`: the largest force the force step measured on that side; magnitudes beyond it are
    left out (beyond_reach), and a row whose target is beyond IN_RANGE of it says so ("in_range":
    False): the spring and motor were shown to hold it, but it is the last stretch of what F0 was
    measured over."""
    beyond = beyond_reach(magnitudes, reached_n)
    kept = [m for m in magnitudes if m not in beyond]
    # a step left out must not leave a hold repeated as a step (5, 10, 10, 5 when 15 is left out)
    magnitudes = [m for i, m in enumerate(kept) if i == 0 or m != kept[i - 1]]
    if not magnitudes:
        return []
    targets = [SIDES[side] * m for m in magnitudes]
    _, measured, estimates = hold_sequence(session, rig, prompter, anchor_mm, side, targets, settle_s, 0.5,
                                       "%s-side steps" % side, preload=True)
    rows = []
    peak = 0.0
    for magnitude, target, m, e in zip(magnitudes, targets, measured, estimates):
        m = float(m)
        rows.append({
            "target": target, "measured": m, "estimate": e, "side": side,
            "phase": "loading" if magnitude > peak else "unloading",  # consecutive magnitudes differ (above)
            "steady_pct": 100.0 * (m - target) / abs(target),
            "estimation_pct": 100.0 * (e - m) / abs(m) if m else float("nan"),
            "reached_n": reached_n,
            "in_range": reached_n is None or magnitude <= IN_RANGE * reached_n,
        })
        peak = max(peak, magnitude)
    rig.no_load()
    return rows


def plot_blocking(path, runs):
    from matplotlib.figure import Figure  # drawn and written without pyplot: no backend is chosen

    fig = Figure(figsize=(7.5, 4.5))
    ax = fig.subplots()
    for name, run in runs:
        ax.plot(run["t"], run["d2"], label="%s: target %+.0f N, ends at %.1f mm" % (name, run["target_n"], run["final"]))
    ax.set_xlabel("time (s)")
    ax.set_ylabel("D2 (mm)")
    ax.set_title("Force control at no load from D2 = 30 mm (paper Fig. 8)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
