"""The project's targets for the paper experiment, and how a run's results are judged against
them: the figures a run is judged on (`headline`: the paper's own and the held-out ones), and
met or not per target (`judged`: on the held-out figures where the run has them). The report
(host/experiments/report.py) and the benches (bench_paper, bench_robustness) judge this one way.
"""

import math

from host.experiments import displacement
from host.guided.stroke import DEFAULT_MM  # a run's results without a stroke: the 0-60 mm actuator's

TARGETS = {  # judged on the held-out figures (host/experiments/held_out.py) when the run has them
    "displacement_mm": 0.1,  # max |error| after calibration over 1-59 mm
    "df_mm": 0.1,  # peak Df residual after the assembly calibration (1 mm bin means)
    "force_pct": 2.0,  # steady-state and estimation errors of the force steps
    "blocking_margin_mm": 5.0,  # "no blocking": the block runs on to within this of the stroke's end (55 mm of 60)
}
# what a run is judged on, in the order reports and benches show them ("force elsewhere": the force
# steps with the gauge away from the anchor the force calibration was made at; same 2 %)
JUDGED = ("Df", "displacement", "no blocking", "force steps", "force elsewhere")


def headline(r):
    """The figures the summary judges, from a run's results (the report's summary, bench/bench_paper.py, bench/bench_robustness.py)."""
    t1 = r["table1"]
    with_df = [b for n, b in r["fig8"] if n == "with Df"]
    return {
        "before": displacement.max_error(r["fig7"]["before"]),
        "after": displacement.max_error(r["fig7"]["after"]),
        # None when every step was beyond what the force step held (none was run)
        "worst_steady_pct": max((abs(x["steady_pct"]) for x in t1), default=None),
        "worst_estimation_pct": max((abs(x["estimation_pct"]) for x in t1), default=None),
        # the paper's Table 1: pulling toward 0 mm, loading
        "paper_rows": [x for x in t1 if x.get("side", "high") == "high" and x.get("phase", "loading") == "loading"],
        "without_df": [b for n, b in r["fig8"] if n == "without Df"],
        "with_df": with_df,
        # a positive force runs the free block toward 60 mm, a negative one toward 0 mm
        "no_blocking": all(ran_to_the_end(b, r.get("stroke_nominal_mm")) for b in with_df),
        **held_out_headline(r),
    }


def ran_to_the_end(run, stroke_mm=None):
    """A no-load force run did not block: it ended within TARGETS["blocking_margin_mm"] of the
    stroke's end its force drives toward (the high end for a positive force)."""
    lo, hi = stroke_mm or DEFAULT_MM
    margin = TARGETS["blocking_margin_mm"]
    return run["final"] >= hi - margin if run["target_n"] > 0 else run["final"] <= lo + margin


def held_out_headline(r):
    """The held-out figures the targets are judged on (None where the run has none)."""
    ho = r.get("held_out") or {}
    forces = ho.get("forces") or []
    away = (ho.get("away") or {}).get("forces") or []
    worst = lambda rows, key: max(abs(x[key]) for x in rows) if rows else None  # noqa: E731
    return {"held_out_df_mm": (ho.get("df") or {}).get("peak_binned_mm"),
            "held_out_displacement_mm": displacement.max_error(ho["positions"]) if ho.get("positions") else None,
            "held_out_steady_pct": worst(forces, "steady_pct"),
            "held_out_estimation_pct": worst(forces, "estimation_pct"),
            "away_steady_pct": worst(away, "steady_pct"),
            "away_estimation_pct": worst(away, "estimation_pct")}


def judged(h, r=None):
    """{target: met?} on the held-out figures, where a run has them, else on the paper's own; the
    displacement on both (positions are never calibration points)."""
    def pick(held, own):
        return own if held is None or (isinstance(held, float) and math.isnan(held)) else held

    df = pick(h.get("held_out_df_mm"), (r or {}).get("fig5", {}).get("peak_after_binned_mm"))
    # no position is a calibration point: the paper's targets count as much as the drawn ones
    pos = max(h["after"], pick(h.get("held_out_displacement_mm"), h["after"]))
    ss = pick(h.get("held_out_steady_pct"), h["worst_steady_pct"])
    est = pick(h.get("held_out_estimation_pct"), h["worst_estimation_pct"])
    away = (h.get("away_steady_pct"), h.get("away_estimation_pct"))
    return {"Df": None if df is None else df <= TARGETS["df_mm"],
            "displacement": pos <= TARGETS["displacement_mm"],
            "no blocking": h["no_blocking"],
            "force steps": None if ss is None or est is None else max(ss, est) <= TARGETS["force_pct"],
            # a run from before these steps existed has none: not judged
            "force elsewhere": None if None in away else max(away) <= TARGETS["force_pct"]}
