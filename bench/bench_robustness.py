"""The defaults on actuators they were not tuned to: random simulated actuators, the paper's
experiments on each, pass rates per target.

    .venv/bin/python bench/bench_robustness.py [--draws 8] [--seed 1] [--out out/robustness] [--doc docs/robustness.md]
    .venv/bin/python bench/bench_robustness.py --only-seed 1007      # rerun one draw

Each draw (seed = --seed * 1000 + i, printed and recorded, so any failure can be rerun alone)
changes boards/sim.json's actuator within the ranges of RANGES below: both pots' knee positions,
sharpness and noise, mounting error on both pots, block friction, spring stiffness, hardening
and preload, motor resistance and constants, gauge drift, and which pot carries the reference
sensor. Then `host experiment paper --port sim --board DRAW.json --out DIR/draw-SEED --fix` runs with
the defaults (about 5-7 minutes each on a 2-core machine; --fix applies the board-file settings
the calibration's bringup recommends, as a user does after reading them: here more reads per
step for noisy pots, which the row's oversample column shows), and the targets of
host/experiments/report.py are judged from its results.json. `boards/sim.json` itself is run as
the first row. A run that stops keeps its partial results.json, and the table says where.
"""

import argparse
import copy
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent

# name: (low, high) of a uniform draw; documented in docs/robustness.md with the results
RANGES = {
    "knee_low_u": (0.08, 0.22),  # first knee, fraction of the track
    "knee_high_u": (0.78, 0.92),
    "knee_halfwidth": (0.03, 0.12),  # how gradual a knee is (0.03 sharp)
    "g_knee_low": (0.05, 0.14),  # output fraction at the knees
    "g_knee_high": (0.86, 0.95),
    "noise_lsb": (1.0, 5.0),
    "mount_peak_mm": (0.5, 3.0),  # peak mounting error of each pot (its share of Df)
    "coulomb_n": (0.1, 1.2),
    "k1_n_per_mm": (7.0, 18.0),
    "k2_n_per_mm2": (0.2, 1.5),
    "preload_n": (5.0, 15.0),
    "resistance_ohm": (2.5, 8.0),
    "k_motor": (0.004, 0.008),  # ke (V s/rad) = kt (N m/A)
    "gauge_drift_n_per_min": (0.1, 0.8),
}


# What an actuator built for the paper's forces must do (Table 1 runs to 15 N): push 20 % more
# than that at the firmware's duty limit (out_limit 8000: 80 %), and hold the force calibration's
# 16 N before the nut nears the cavity wall. A draw that cannot is redrawn from the same
# generator (so the seed still fixes the actuator) and the number of redraws is recorded.
NEED_PUSH_N = 18.0
NEED_SPRING_N = 16.0
DUTY_LIMIT = 0.8
CAVITY_NEAR_MM = 1.8


def capability(a, supply_volts=6.0):
    """(push N at the duty limit, spring force N at CAVITY_NEAR_MM) of actuator parameters `a`."""
    import math

    m, s, sp = a["motor"], a["screw"], a["springs"]
    g = m.get("gear_ratio", 1.0) * 2 * math.pi / (s["lead_mm"] / 1000.0)
    push = s["efficiency"] * m["kt_nm_per_a"] * g * supply_volts * DUTY_LIMIT / m["resistance_ohm"]
    k1, k2, d = sp["k1_n_per_mm"], sp["k2_n_per_mm2"], CAVITY_NEAR_MM
    r = sp["preload_n"] / (k1 / 2.0)
    if d > r:
        spring = k1 * r + k2 * r * r + (k1 + 2 * k2 * r) / 2.0 * (d - r)
    else:
        spring = k1 * d + k2 * d * d
    return push, spring


def draw(base, seed, supply_volts=6.0):
    """A copy of the actuator `base` changed within RANGES by a generator seeded with `seed`, redrawn
    (same generator) until it can do the paper's forces (capability): (actuator, redraws)."""
    rng = np.random.default_rng(seed)
    redraws = 0
    while True:
        a = _draw_once(base, rng)
        push, spring = capability(a, supply_volts)
        if push >= NEED_PUSH_N and spring >= NEED_SPRING_N:
            return a, redraws
        redraws += 1


def _draw_once(base, rng):
    u = lambda name: float(rng.uniform(*RANGES[name]))  # noqa: E731
    a = copy.deepcopy(base)
    for name in ("pot1", "pot2"):
        pot = a["pots"][name]
        g0, g3 = pot["curve"][0][1], pot["curve"][3][1]
        pot["curve"] = [[0.0, g0], [u("knee_low_u"), u("g_knee_low")], [u("knee_high_u"), u("g_knee_high")], [1.0, g3]]
        pot["knee_halfwidth"] = min(u("knee_halfwidth"), 0.9 * pot["curve"][1][0], 0.9 * (1 - pot["curve"][2][0]))
        pot["noise_lsb"] = u("noise_lsb")
        # the mounting error keeps the shape of sim.json's pot 1 (bowed and tilted), scaled to its
        # own peak and sign for each pot, so both pots carry some of Df
        shape = base["pots"]["pot1"]["mount_error"]["coeffs_mm"]
        v = np.linspace(-1, 1, 201)
        peak = max(abs(np.polyval(shape[::-1], v)))
        scale = u("mount_peak_mm") / peak * (1 if rng.uniform() < 0.5 else -1)
        pot["mount_error"]["coeffs_mm"] = [c * scale for c in shape]
    a["block"]["coulomb_n"] = u("coulomb_n")
    a["springs"]["k1_n_per_mm"] = u("k1_n_per_mm")
    a["springs"]["k2_n_per_mm2"] = u("k2_n_per_mm2")
    a["springs"]["preload_n"] = u("preload_n")
    a["motor"]["resistance_ohm"] = u("resistance_ohm")
    a["motor"]["ke_v_s_per_rad"] = a["motor"]["kt_nm_per_a"] = u("k_motor")
    a["gauge"]["drift_n_per_min"] = u("gauge_drift_n_per_min")
    a["reference"]["mounted_on"] = "pot1" if rng.uniform() < 0.5 else "pot2"
    return a


def describe(a, supply_volts, redraws):
    """The draw's figures that explain a miss: friction, spring, push, pot noise, pot 2's mounting
    error at the stroke ends (it moves the end stops in pot 2's frame), the reference's pot."""
    push, spring = capability(a, supply_volts)
    e2 = a["pots"]["pot2"]["mount_error"]["coeffs_mm"]
    return {"friction_n": a["block"]["coulomb_n"], "k1_n_per_mm": a["springs"]["k1_n_per_mm"],
            "k2_n_per_mm2": a["springs"]["k2_n_per_mm2"], "preload_n": a["springs"]["preload_n"],
            "push_n": push, "spring_at_1.8mm_n": spring,
            "noise_lsb": [a["pots"][p]["noise_lsb"] for p in ("pot1", "pot2")],
            "pot2_mount_mm_at_0_60": [float(np.polyval(e2[::-1], v)) for v in (-1.0, 1.0)],
            "reference": a["reference"]["mounted_on"], "redraws": redraws}


def judge(results):
    """{target: True/False/None} from a run's results.json (None: the run stopped before it)."""
    from host.experiments.report import TARGETS, headline

    out = {"Df": None, "displacement": None, "no blocking": None, "force steps": None}
    if "fig5" in results and "peak_after_binned_mm" in results["fig5"]:
        out["Df"] = results["fig5"]["peak_after_binned_mm"] <= TARGETS["df_mm"]
    try:
        h = headline(results)
    except (KeyError, ValueError, TypeError):
        h = None
    if "fig7" in results and "after" in results["fig7"]:
        from host.experiments.displacement import max_error

        out["displacement"] = max_error(results["fig7"]["after"]) <= TARGETS["displacement_mm"]
    if h is not None:
        out["no blocking"] = h["no_blocking"]
        out["force steps"] = max(h["worst_steady_pct"], h["worst_estimation_pct"]) <= TARGETS["force_pct"]
    elif "fig8" in results:
        with_df = [b for n, b in results["fig8"] if n == "with Df"]
        out["no blocking"] = all((b["final"] >= TARGETS["blocking_from_mm"]) if b["target_n"] > 0
                                 else (b["final"] <= 60.0 - TARGETS["blocking_from_mm"]) for b in with_df) if with_df else None
    return out


def figures(results):
    from host.experiments.displacement import max_error

    f = {}
    if "fig5" in results:
        f["Df mm"] = "%.3f" % results["fig5"].get("peak_after_binned_mm", float("nan"))
    if "fig7" in results and "after" in results["fig7"]:
        f["displacement mm"] = "%.3f" % max_error(results["fig7"]["after"])
        f["unsettled"] = sum(1 for r in results["fig7"]["after"] if not r.get("settled", True))
    if "table1" in results:
        t1 = results["table1"]
        f["force %"] = "%.1f / %.1f" % (max(abs(x["steady_pct"]) for x in t1), max(abs(x["estimation_pct"]) for x in t1))
    if "stopped" in results:
        f["stopped"] = "%s: %s" % (results["stopped"]["phase"], results["stopped"]["why"])
    return f


def run_one(board_path, out_dir):
    cmd = [sys.executable, "-m", "host", "experiment", "paper", "--port", "sim", "--board", str(board_path), "--out", str(out_dir),
           "--fix"]
    t0 = time.monotonic()
    proc = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True)
    wall = time.monotonic() - t0
    results_path = Path(out_dir) / "results.json"
    results = json.loads(results_path.read_text()) if results_path.exists() else {}
    last = (proc.stderr.strip().splitlines() or [""])[-1]
    return results, wall, proc.returncode, last


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--draws", type=int, default=8, help="random actuators besides boards/sim.json (default 8)")
    ap.add_argument("--seed", type=int, default=1, help="draw i uses seed SEED*1000+i (default 1)")
    ap.add_argument("--only-seed", type=int, help="run just this draw's seed")
    ap.add_argument("--no-base", action="store_true", help="skip the boards/sim.json row")
    ap.add_argument("--out", default="out/robustness", help="where the boards and runs go")
    ap.add_argument("--doc", help="write the table and ranges to this Markdown file")
    ap.add_argument("--reuse", action="store_true",
                    help="keep the rows whose run already finished in --out (results.json there): an interrupted bench "
                         "goes on where it stopped")
    a = ap.parse_args(argv)
    board = json.loads((REPO / "boards" / "sim.json").read_text())
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    seeds = [a.only_seed] if a.only_seed is not None else [a.seed * 1000 + i for i in range(a.draws)]
    plan = ([] if (a.no_base or a.only_seed is not None) else [("sim.json", None)]) + [("draw", s) for s in seeds]
    for kind, seed in plan:
        if seed is None:
            path, name = REPO / "boards" / "sim.json", "sim.json"
            actuator, redraws = board["actuator"], 0
        else:
            actuator, redraws = draw(board["actuator"], seed, board["supply_volts"])
            b = dict(board, name="sim", actuator=actuator)
            b.pop("sources", None)
            path = out / ("board-%d.json" % seed)
            name = "seed %d" % seed
        run_dir = out / ("run-%s" % (seed if seed is not None else "base"))
        done = run_dir / "results.json"
        results = json.loads(done.read_text()) if a.reuse and done.exists() else {}
        if a.reuse and ((run_dir / "row.json").exists() or "timings" in results or "stopped" in results):  # it ended
            kept = json.loads((run_dir / "row.json").read_text()) if (run_dir / "row.json").exists() else {}
            wall, code, last = kept.get("wall_s"), kept.get("exit"), kept.get("last_line", "")
            print("%s: kept from %s" % (name, run_dir), file=sys.stderr, flush=True)
        else:
            if seed is not None:  # bringup's --fix edits this file: write it only for a run
                path.write_text(json.dumps(b, indent=1))
            print("%s: running (about 5 minutes)..." % name, file=sys.stderr, flush=True)
            results, wall, code, last = run_one(path, run_dir)
            fixed = sorted(run_dir.glob("board-*.json"))  # bringup's fix of a shipped board file lands here
            kept = {"wall_s": wall, "exit": code, "last_line": last,
                    "oversample": json.loads((fixed[0] if fixed else path).read_text()).get("oversample")}
            (run_dir / "row.json").write_text(json.dumps(kept))
        verdict = judge(results)
        row = {"name": name, "seed": seed, "wall_s": wall, "exit": code, "last_line": last,
               "verdict": verdict, "figures": figures(results), "actuator": describe(actuator, board["supply_volts"], redraws)}
        row["actuator"]["oversample"] = kept.get("oversample")
        rows.append(row)
        print("%s: %s %s (%s s, exit %s)" % (name, verdict, row["figures"], "-" if wall is None else "%.0f" % wall, code), flush=True)
    (out / "summary.json").write_text(json.dumps(rows, indent=1))
    targets = ("Df", "displacement", "no blocking", "force steps")
    lines = ["| actuator | " + " | ".join(targets) + " | figures | wall s |", "| --- |" + " --- |" * (len(targets) + 2)]
    for r in rows:
        cells = [{True: "met", False: "**missed**", None: "not run"}[r["verdict"][t]] for t in targets]
        figs = "; ".join("%s %s" % kv for kv in r["figures"].items())
        wall = "-" if r["wall_s"] is None else "%.0f" % r["wall_s"]
        lines.append("| %s | %s | %s | %s |" % (r["name"], " | ".join(cells), figs, wall))
    lines += ["", "| actuator | friction N | k1 N/mm | k2 N/mm^2 | preload N | push N | spring at 1.8 mm N | pot noise LSB | "
              "pot 2 mount error at 0 / 60 mm | reference | redraws | oversample after bringup |", "| --- |" + " --- |" * 11]
    for r in rows:
        d = r["actuator"]
        lines.append("| %s | %.2f | %.1f | %.2f | %.1f | %.1f | %.1f | %.1f / %.1f | %+.2f / %+.2f | %s | %d | %s |" % (
            r["name"], d["friction_n"], d["k1_n_per_mm"], d["k2_n_per_mm2"], d["preload_n"], d["push_n"],
            d["spring_at_1.8mm_n"], d["noise_lsb"][0], d["noise_lsb"][1], d["pot2_mount_mm_at_0_60"][0],
            d["pot2_mount_mm_at_0_60"][1], d["reference"], d["redraws"], d.get("oversample")))
    rate = {t: sum(1 for r in rows if r["verdict"][t]) for t in targets}
    lines.append("")
    lines.append("Pass rates: " + ", ".join("%s %d/%d" % (t, rate[t], len(rows)) for t in targets))
    table = "\n".join(lines)
    print(table)
    if a.doc:
        ranges = "\n".join("| %s | %g | %g |" % (k, lo, hi) for k, (lo, hi) in RANGES.items())
        Path(a.doc).write_text(
            "# Robustness: the defaults on actuators they were not tuned to\n\n"
            "Made by `.venv/bin/python bench/bench_robustness.py %s` (simulated actuators; every "
            "figure measured in that run).\n\n%s\n\n## Ranges of the draws\n\n| parameter | low | high |\n"
            "| --- | --- | --- |\n%s\n" % (" ".join(sys.argv[1:]), table, ranges))
    return 0


if __name__ == "__main__":
    sys.exit(main())
