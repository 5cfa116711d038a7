"""Run the paper's experiments on the virtual board, time them, and record the reports in docs/.

    .venv/bin/python bench/bench_paper.py [--out out/paper] [--doc docs/paper-experiments.md] [--only default|paper]

Runs `host experiment paper --port sim --out DIR` twice: with lsea-kit's defaults (into DIR) and
with `--paper-method` (the paper's choices: BCM-3 pots, quartic Df, quadratic force fits without
friction, gauge on one side; into DIR-paper-method). Each run calibrates first, as `host
calibrate --port sim --yes` does. Prints the wall time of each, and writes DOC: the commands, the
machine, a side-by-side summary (both runs' figures, taken from their results.json) and a copy of
each report.md (figure links pointing into the output directories, which are not committed: run
the command to get the PNGs).
"""

import argparse
import json
import os
import platform
import re
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
RUNS = (("default", "lsea-kit defaults", []), ("paper", "the paper's method (--paper-method)", ["--paper-method"]))


def _run(out, extra):
    cmd = ["host", "experiment", "paper", "--port", "sim", "--out", out] + extra
    t0 = time.monotonic()
    proc = subprocess.run([sys.executable, "-m"] + cmd, cwd=REPO)
    return cmd, time.monotonic() - t0, proc.returncode


def _figures(results):
    """The summary figures of one run's results.json (those the report judges)."""
    from host.experiments.targets import headline

    h = headline(results)
    t1 = results["table1"]
    return {
        "Df peak after, 1 mm bin means (mm)": "%.3f (order %d)" % (results["fig5"]["peak_after_binned_mm"], results["fig5"]["order"]),
        "displacement max error 1-59 mm (mm)": "%.3f" % h["after"],
        "no-load force runs, D2 at the end (mm)": ", ".join("%+.0f N: %.1f" % (b["target_n"], b["final"]) for b in h["with_df"]),
        "dead zone (N)": "%.1f" % results["dead_zone"]["dead_zone_n"],
        "Table 1 -5/-10/-15 N steady-state (%)": " / ".join("%+.1f" % x["steady_pct"] for x in h["paper_rows"]),
        "Table 1 -5/-10/-15 N estimation (%)": " / ".join("%+.1f" % x["estimation_pct"] for x in h["paper_rows"]),
        "worst steady-state / estimation error, all steps (%)": "%.1f / %.1f over %d steps" % (
            h["worst_steady_pct"], h["worst_estimation_pct"], len(t1)),
        "pot models": "pot 1 %s, pot 2 %s" % (results["pot_models"]["pot1"], results["pot_models"]["pot2"]),
        "wall time (s)": "%.0f" % results["timings"]["total"],
    }


PAPER = {
    "Df peak after, 1 mm bin means (mm)": "0.9 (peak, order 4)",
    "displacement max error 1-59 mm (mm)": "4.2 (1-60 mm)",
    "no-load force runs, D2 at the end (mm)": "+5 N: runs to 60",
    "dead zone (N)": "about 0.4",
    "Table 1 -5/-10/-15 N steady-state (%)": "-4.6 / -7.0 / 4.0",
    "Table 1 -5/-10/-15 N estimation (%)": "-2.5 / -5.6 / 2.8",
    "worst steady-state / estimation error, all steps (%)": "7.0 / 5.6 over 3 steps",
    "pot models": "BCM-3",
    "wall time (s)": "-",
}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="out/paper")
    ap.add_argument("--doc", default=str(REPO / "docs" / "paper-experiments.md"))
    ap.add_argument("--only", choices=[k for k, _, _ in RUNS], help="run one configuration (the doc then has only it)")
    args = ap.parse_args(argv)
    done = []
    for key, title, extra in RUNS:
        if args.only and key != args.only:
            continue
        out = args.out if key == "default" else args.out.rstrip("/") + "-paper-method"
        cmd, wall, code = _run(out, extra)
        if code:
            print("experiment failed (exit %d): %s" % (code, " ".join(cmd)))
            return code
        results = json.loads((REPO / out / "results.json").read_text())
        print("%s: wall time %.0f s" % (title, wall))
        done.append((key, title, cmd, wall, out, results))

    lines = [
        "# The paper's experiments (recorded runs)",
        "",
        "Recorded by `.venv/bin/python bench/bench_paper.py` on %s (Python %s, %d CPUs reported by the OS), "
        "which ran" % (platform.platform(terse=True), platform.python_version(), os.cpu_count() or 0),
        "",
    ]
    for _, title, cmd, wall, _, _ in done:
        lines += ["    .venv/bin/python -m %s" % " ".join(cmd), "", "(%s: %.0f s of wall time, calibration included)" % (title, wall), ""]
    lines += [
        "Everything runs on the simulated actuator (the virtual board: the real firmware on the MicroPython "
        "unix port, with the physical model of docs/simulated-actuator.md behind its ADC and PWM). The "
        "figures (PNG) are written to the output directories by those commands and are not committed; the "
        "links below point there. Re-running gives slightly different numbers (sensor noise, gauge drift, "
        "wall-clock timing of the virtual board), which is why this page is a record, not a specification. "
        "What the experiments do: docs/guided-calibration.md and host/experiments/.",
        "",
        "## Side by side",
        "",
        "| figure | paper | " + " | ".join(title for _, title, _, _, _, _ in done) + " |",
        "| --- | --- | " + " | ".join("---" for _ in done) + " |",
    ]
    figs = [_figures(r) for _, _, _, _, _, r in done]
    for name in PAPER:
        lines.append("| %s | %s | %s |" % (name, PAPER[name], " | ".join(f[name] for f in figs)))
    lines.append("")
    for _, title, _, _, out, _ in done:
        report = (REPO / out / "report.md").read_text()
        rel = Path(out).as_posix().rstrip("/")
        body = re.sub(r"\]\((?!http)([^)]+)\)", lambda m, rel=rel: "](../%s/%s)" % (rel, m.group(1)), report)
        body = re.sub(r"^## ", "### ", body, flags=re.M)
        body = body.replace("# The paper's experiments, measured on", "## Report (%s), measured on" % title, 1)
        lines.append(body)
    Path(args.doc).write_text("\n".join(lines) + "\n")
    print("wrote %s" % args.doc)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
