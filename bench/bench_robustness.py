"""The defaults on actuators they were not tuned to: random simulated actuators, the paper's
experiments on each, pass rates per target, judged on the held-out figures.

    .venv/bin/python bench/bench_robustness.py --fresh [--draws 12] --out out/rob --doc docs/robustness.md
    .venv/bin/python bench/bench_robustness.py --seed 1 [--draws 8] ...   # the development seeds 1000-1007
    .venv/bin/python bench/bench_robustness.py --only-seed 2026112603     # rerun one draw
    .venv/bin/python bench/bench_robustness.py --fresh --hour 2026112711 --reuse ...  # finish that hour's run

Seeds. Draw i uses seed SEED*1000+i with `--seed` (default 1: seeds 1000-1007, which at least six
fixes were made against: development data, not evaluation). `--fresh` draws an evaluation base
from the date and hour (YYYYMMDDHH*100+i, printed and recorded): seeds no fix was made against
when they first run. A fix made after looking at a fresh run turns its seeds into development
data too; the doc records which run was which.

Each draw changes boards/sim.json's actuator within RANGES (testkit/drawn_actuators.py) (uniform draws; the choices in
CHOICES): both pots' knee positions, sharpness, noise and the rail a lifted wiper goes to, a
mounting error of its own random shape and size on each pot, the reference sensor's and the
gauge's noise, the gauge's stiffness and drift, block friction (Coulomb and viscous), spring
stiffness, hardening, preload and damping, the masses, motor resistance and constants, screw
lead and gear ratio, the board's supply voltage (5 V of a USB-powered board to 9 V), and which
pot carries the reference sensor, and the stroke (40 to 80 mm: 0..L, or -22..58 mm for 80, testkit.actuators.frame_low; the board file's `stroke_mm`
says it, as a user's would). Then `host experiment
paper --port sim --board DRAW.json --out DIR/run-SEED --fix` runs with the defaults (about 6-9
minutes each on a 2-core machine; --fix applies the board-file settings bringup recommends, as a
user does after reading them: here more reads per step for noisy pots, which the row's
oversample column shows), and the targets of host/experiments/report.py are judged from its
results.json on the held-out figures (host/experiments/held_out.py). `boards/sim.json` itself is
run as the first row. A run that stops keeps its partial results.json, and the table says where.
"""

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path


REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
from testkit.drawn_actuators import CHOICES, RANGES, describe, draw  # noqa: E402

def judge(results):
    """{target: True/False/None} from a run's results.json, on the held-out figures where the run
    has them (host.experiments.targets.judged); None: the run stopped before it."""
    from host.experiments.targets import JUDGED, TARGETS, headline, judged

    out = dict.fromkeys(JUDGED)
    try:
        return judged(headline(results), results)
    except (KeyError, ValueError, TypeError):
        pass
    ho = results.get("held_out") or {}
    if (ho.get("df") or {}).get("peak_binned_mm") is not None:
        out["Df"] = ho["df"]["peak_binned_mm"] <= TARGETS["df_mm"]
    elif "fig5" in results and "peak_after_binned_mm" in results["fig5"]:
        out["Df"] = results["fig5"]["peak_after_binned_mm"] <= TARGETS["df_mm"]
    if "fig7" in results and "after" in results["fig7"]:
        from host.experiments.displacement import max_error

        rows = ho.get("positions") or results["fig7"]["after"]
        out["displacement"] = max_error(rows) <= TARGETS["displacement_mm"]
    if "fig8" in results:
        from host.experiments.targets import ran_to_the_end

        with_df = [b for n, b in results["fig8"] if n == "with Df"]
        out["no blocking"] = all(ran_to_the_end(b, results.get("stroke_nominal_mm")) for b in with_df) if with_df else None
    return out


def figures(results):
    """The figures of a row: held out first (judged), the paper's own (in-sample) in brackets."""
    from host.experiments.displacement import max_error

    f = {}
    ho = results.get("held_out") or {}
    if "fig5" in results:
        f["Df mm"] = "%.3f" % (ho.get("df") or {}).get("peak_binned_mm", float("nan")) + \
            " (fit %.3f)" % results["fig5"].get("peak_after_binned_mm", float("nan"))
    if "fig7" in results and "after" in results["fig7"]:
        held = ho.get("positions") or []
        f["displacement mm"] = ("%.3f" % max_error(held) if held else "-") + " (paper's targets %.3f)" % max_error(results["fig7"]["after"])
        f["unsettled"] = sum(1 for r in results["fig7"]["after"] + held if not r.get("settled", True))
    if "table1" in results:
        t1 = results["table1"]
        forces = ho.get("forces") or []
        held = ("%.1f / %.1f" % (max(abs(x["steady_pct"]) for x in forces), max(abs(x["estimation_pct"]) for x in forces))
                if forces else "-")
        own = ("%.1f / %.1f" % (max(abs(x["steady_pct"]) for x in t1), max(abs(x["estimation_pct"]) for x in t1))
               if t1 else "none run: beyond the force range")
        f["force %"] = "%s (5/10/15 N %s; %d held-out steps)" % (held, own, len(forces))
        away = (ho.get("away") or {})
        if away.get("forces"):
            f["force % elsewhere"] = "%.1f / %.1f (%d steps at %g mm, calibrated at %g mm)" % (
                max(abs(x["steady_pct"]) for x in away["forces"]), max(abs(x["estimation_pct"]) for x in away["forces"]),
                len(away["forces"]), away["anchor_mm"], away["calibrated_at_mm"])
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


BEGIN, END = "<!-- bench_robustness.py: begin -->", "<!-- bench_robustness.py: end -->"


def write_doc(path, table):
    """The run's tables and the draws' ranges into `path`, between the BEGIN and END markers (the
    rest of the file, written by hand, is kept); a file without them gets them at its top."""
    ranges = "\n".join("| %s | %g | %g |" % (k, lo, hi) for k, (lo, hi) in RANGES.items())
    choices = "\n".join("| %s | %s |" % (k, " or ".join(v)) for k, v in CHOICES.items())
    block = ("%s\nMade by `.venv/bin/python bench/bench_robustness.py %s` (simulated actuators; every figure measured "
             "in that run; the bench writes from here to the end marker, the rest is written by hand). Targets are judged "
             "on the held-out figures; the paper's own (in-sample) figures are in brackets.\n\n%s\n\n### Ranges of the "
             "draws\n\n| parameter | low | high |\n| --- | --- | --- |\n%s\n\n| choice | one of |\n| --- | --- |\n%s\n%s"
             % (BEGIN, " ".join(sys.argv[1:]), table, ranges, choices, END))
    text = path.read_text() if path.exists() else ""
    if BEGIN in text and END in text:
        text = text[:text.index(BEGIN)] + block + text[text.index(END) + len(END):]
    else:
        head, _, rest = text.partition("\n")
        text = (head + "\n\n" if head else "# Robustness\n\n") + block + "\n" + rest
    path.write_text(text)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--draws", type=int, default=8, help="random actuators besides boards/sim.json (default 8)")
    ap.add_argument("--seed", type=int, default=1, help="draw i uses seed SEED*1000+i (default 1: the development seeds)")
    ap.add_argument("--fresh", action="store_true",
                    help="evaluation seeds from the date and hour, YYYYMMDDHH*100+i, printed")
    ap.add_argument("--hour", type=int, metavar="YYYYMMDDHH",
                    help="with --fresh --reuse: the hour whose seeds to draw (default: now), to finish an evaluation "
                         "run after its hour (its seeds are not fresh any more, so --reuse is required)")
    ap.add_argument("--first-draw", type=int, default=0, metavar="I",
                    help="with --fresh: draws I .. I+DRAWS-1 of the hour (default 0): a second run in the same hour "
                         "after a first was stopped, on seeds none was run with")
    ap.add_argument("--only-seed", type=int, help="run just this draw's seed")
    ap.add_argument("--no-base", action="store_true", help="skip the boards/sim.json row")
    ap.add_argument("--out", default="out/robustness", help="where the boards and runs go")
    ap.add_argument("--doc", help="write the table and ranges to this Markdown file")
    ap.add_argument("--boards-only", action="store_true",
                    help="write the drawn board files (board-SEED.json in --out) and run nothing: actuators for the "
                         "offline benches (bench_force_steps_offline.py --runs OUT --exact --oversample 16)")
    ap.add_argument("--reuse", action="store_true",
                    help="keep the rows whose run already finished in --out (results.json there): an interrupted bench "
                         "goes on where it stopped")
    a = ap.parse_args(argv)
    if a.hour is not None and not (a.fresh and (a.reuse or a.boards_only)):
        ap.error("--hour finishes an evaluation run: it needs --fresh and --reuse (or --boards-only)")
    board = json.loads((REPO / "boards" / "sim.json").read_text())
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    if a.only_seed is not None:
        seeds = [a.only_seed]
    elif a.fresh:
        base = (a.hour if a.hour is not None else int(time.strftime("%Y%m%d%H"))) * 100
        seeds = [base + i for i in range(a.first_draw, a.first_draw + a.draws)]
        print("evaluation seeds %d-%d (%s)" % (seeds[0], seeds[-1], "from the date and hour: none was run before this hour"
                                                 if a.hour is None else "the run of hour %d, finished" % a.hour),
              file=sys.stderr)
    else:
        seeds = [a.seed * 1000 + i for i in range(a.draws)]
    plan = ([] if (a.no_base or a.only_seed is not None) else [("sim.json", None)]) + [("draw", s) for s in seeds]
    for _kind, seed in plan:
        if seed is None:
            path, name = REPO / "boards" / "sim.json", "sim.json"
            actuator, volts, redraws = board["actuator"], board["supply_volts"], 0
        else:
            # seeds below 10000 (the development ones) keep the board's supply, as their runs did
            actuator, volts, redraws = draw(board["actuator"], seed, board["supply_volts"] if seed < 10000 else None)
            b = dict(board, name="sim", actuator=actuator, supply_volts=round(volts, 2),
                     stroke_mm=list(actuator["block"]["stroke_mm"]))
            b.pop("sources", None)
            path = out / ("board-%d.json" % seed)
            name = "seed %d" % seed
        if a.boards_only:
            if seed is not None:
                path.write_text(json.dumps(b, indent=1))
                print("%s: %s" % (name, path), file=sys.stderr, flush=True)
            continue
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
            print("%s: running (about 6-9 minutes)..." % name, file=sys.stderr, flush=True)
            results, wall, code, last = run_one(path, run_dir)
            fixed = sorted(run_dir.glob("board-*.json"))  # bringup's fix of a shipped board file lands here
            kept = {"wall_s": wall, "exit": code, "last_line": last,
                    "oversample": json.loads((fixed[0] if fixed else path).read_text()).get("oversample")}
            (run_dir / "row.json").write_text(json.dumps(kept))
        verdict = judge(results)
        row = {"name": name, "seed": seed, "wall_s": wall, "exit": code, "last_line": last,
               "verdict": verdict, "figures": figures(results), "actuator": describe(actuator, volts, redraws),
               "held_out_seed": (results.get("held_out") or {}).get("seed")}
        row["actuator"]["oversample"] = kept.get("oversample")
        rows.append(row)
        print("%s: %s %s (%s s, exit %s)" % (name, verdict, row["figures"], "-" if wall is None else "%.0f" % wall, code), flush=True)
    if a.boards_only:
        return 0
    (out / "summary.json").write_text(json.dumps(rows, indent=1))
    from host.experiments.targets import JUDGED as targets
    lines = ["| actuator | " + " | ".join(targets) + " | figures | wall s |", "| --- |" + " --- |" * (len(targets) + 2)]
    for r in rows:
        cells = [{True: "met", False: "**missed**", None: "not run"}[r["verdict"][t]] for t in targets]
        figs = "; ".join("%s %s" % kv for kv in r["figures"].items())
        wall = "-" if r["wall_s"] is None else "%.0f" % r["wall_s"]
        lines.append("| %s | %s | %s | %s |" % (r["name"], " | ".join(cells), figs, wall))
    lines += ["", "| actuator | friction N | viscous N s/m | k1 N/mm | k2 N/mm^2 | preload N | supply V | lead mm x gear | "
              "push N | spring at 1.8 mm N | block kg | pot noise LSB | ref / gauge noise LSB | gauge N/mm | "
              "pot 2 mount error at stroke ends mm | reference | stroke mm | redraws | oversample after bringup | held-out seed |",
              "| --- |" + " --- |" * 19]
    for r in rows:
        d = r["actuator"]
        lines.append("| %s | %.2f | %.1f | %.1f | %.2f | %.1f | %.1f | %.2f x %.2f | %.1f | %.1f | %.3f | %.1f / %.1f | %.1f / %.1f "
                     "| %.0f | %+.2f / %+.2f | %s | %.1f | %d | %s | %s |" % (
                         r["name"], d["friction_n"], d["viscous"], d["k1_n_per_mm"], d["k2_n_per_mm2"], d["preload_n"],
                         d["supply_v"], d["lead_mm"], d["gear"], d["push_n"], d["spring_at_1.8mm_n"], d["block_kg"],
                         d["noise_lsb"][0], d["noise_lsb"][1], d["ref_noise_lsb"], d["gauge_noise_lsb"], d["gauge_n_per_mm"],
                         d["pot2_mount_mm_at_0_60"][0], d["pot2_mount_mm_at_0_60"][1], d["reference"], d["stroke_mm"], d["redraws"],
                         d.get("oversample"), r.get("held_out_seed")))
    rate = {t: sum(1 for r in rows if r["verdict"][t]) for t in targets}
    lines.append("")
    lines.append("Pass rates: " + ", ".join("%s %d/%d" % (t, rate[t], len(rows)) for t in targets))
    table = "\n".join(lines)
    print(table)
    if a.doc:
        write_doc(Path(a.doc), table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
