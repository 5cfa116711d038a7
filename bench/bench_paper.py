"""Run the paper's experiments on the virtual board, time them, and record the report in docs/.

    .venv/bin/python bench/bench_paper.py [--out out/paper] [--doc docs/paper-experiments.md] [-- extra args]

Runs `host experiment paper --port sim --out DIR` (which calibrates first, as `host calibrate
--port sim --yes` does), prints the wall time of each phase as the report records it, and writes
DOC: the command, the wall time, and a copy of DIR/report.md (figure links pointing into DIR,
which is not committed: run the command to get the PNGs).
"""

import argparse
import platform
import re
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="out/paper")
    ap.add_argument("--doc", default=str(REPO / "docs" / "paper-experiments.md"))
    ap.add_argument("extra", nargs="*", help="extra arguments for host experiment paper")
    args = ap.parse_args(argv)
    cmd = ["host", "experiment", "paper", "--port", "sim", "--out", args.out] + args.extra
    t0 = time.monotonic()
    proc = subprocess.run([sys.executable, "-m"] + cmd, cwd=REPO)
    wall = time.monotonic() - t0
    if proc.returncode:
        print("experiment failed (exit %d)" % proc.returncode)
        return proc.returncode
    report = (REPO / args.out / "report.md").read_text()
    timings = re.search(r"Timings: (.*)\.", report)
    print("wall time %.0f s (%s)" % (wall, timings.group(1) if timings else "no timings in the report"))
    rel = Path(args.out).as_posix().rstrip("/")
    body = re.sub(r"\]\((?!http)([^)]+)\)", lambda m: "](../%s/%s)" % (rel, m.group(1)), report)
    body = body.replace("# The paper's experiments", "## Report", 1)
    header = [
        "# The paper's experiments (recorded run)",
        "",
        "Recorded by `.venv/bin/python bench/bench_paper.py`, which ran",
        "",
        "    .venv/bin/python -m %s" % " ".join(cmd),
        "",
        "on %s (Python %s, %d CPUs reported by the OS): %.0f s of wall time in total, calibration "
        "included. The figures (PNG) are written to `%s/` by that command and are not committed; the "
        "links below point there. Re-running gives slightly different numbers (sensor noise, wall-clock "
        "timing of the virtual board), which is why this page is a record, not a specification. What the "
        "experiments do: docs/guided-calibration.md and host/experiments/." % (
            platform.platform(terse=True), platform.python_version(), __import__("os").cpu_count() or 0, wall, rel),
        "",
    ]
    Path(args.doc).write_text("\n".join(header) + "\n" + body)
    print("wrote %s" % args.doc)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
