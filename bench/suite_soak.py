"""Run the whole test suite N times in a row and count each test's outcomes: is it flaky?

    .venv/bin/python bench/suite_soak.py --reps 3                 # as the machine is
    .venv/bin/python bench/suite_soak.py --reps 3 --busy 2        # two CPU-bound processes meanwhile
    .venv/bin/python bench/suite_soak.py --reps 5 -- tests/sim/test_machine.py   # a subset

Each repetition is `python -m pytest -q -n 3 --dist loadfile -rA --junitxml=OUT/rep-K.xml` (the README's test
command; `--workers 0` runs without pytest-xdist; plus anything after `--`), run from the repository; per-test outcomes come from the junit XML. `--busy N` starts N
busy-looping processes before the first repetition and kills them after the last, whatever
happens (normal end, an exception, Ctrl-C, SIGTERM; each also exits by itself once this script
is gone, even after a SIGKILL). The load average (`/proc/loadavg`) is printed before and after
every repetition: on a shared machine "quiet" means only what was measured, so say it.

Printed at the end: each repetition's wall time, load and counts, then every test that did not
pass every time with its pass/fail/error/skip counts (and the first line of its first failure),
and the totals. The same goes to OUT/summary.md; OUT defaults to out/soak-<mode>-<time>.
"""

import argparse
import collections
import os
import signal
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent

# A burner spins in chunks and checks between them that its parent (this script) is still there.
BURNER = """
import os, sys
parent = int(sys.argv[1])
while os.getppid() == parent:
    for _ in range(2000000):
        pass
"""


def loadavg():
    try:
        return " ".join(Path("/proc/loadavg").read_text().split()[:3])
    except OSError:
        return os.popen("uptime").read().strip()


def start_burners(n):
    return [subprocess.Popen([sys.executable, "-c", BURNER, str(os.getpid())],
                             stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            for _ in range(n)]


def stop_burners(procs):
    for p in procs:
        if p.poll() is None:
            p.kill()
    for p in procs:
        try:
            p.wait(timeout=10)
        except subprocess.TimeoutExpired:
            pass


def outcomes(xml_path):
    """{test id: (outcome, first line of the message)} from a junit XML file."""
    out = {}
    try:
        root = ET.parse(xml_path).getroot()
    except (OSError, ET.ParseError):
        return out
    for case in root.iter("testcase"):
        name = "%s::%s" % (case.get("classname", ""), case.get("name", ""))
        outcome, message = "passed", ""
        for child in case:
            if child.tag in ("failure", "error", "skipped"):
                outcome = {"failure": "failed", "error": "error", "skipped": "skipped"}[child.tag]
                message = (child.get("message") or child.text or "").strip().splitlines()[:1]
                message = message[0][:160] if message else ""
                break
        out[name] = (outcome, message)
    return out


def _as_from_a_terminal():
    """The suite gets the default SIGINT, as when run from a terminal: a soak started with
    `nohup ... &` inherits SIGINT ignored, which no CI run or person at a terminal has."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def run_rep(k, out_dir, pytest_args, workers=3):
    xml = out_dir / ("rep-%d.xml" % k)
    log = out_dir / ("rep-%d.log" % k)
    load_before = loadavg()
    t0 = time.monotonic()
    with open(log, "w") as f:
        parallel = ["-n", str(workers), "--dist", "loadfile"] if workers else []
        code = subprocess.call([sys.executable, "-m", "pytest", "-q", *parallel, "-rA", "-p", "no:cacheprovider",
                                "--junitxml", str(xml), *pytest_args], cwd=str(REPO), stdout=f, stderr=subprocess.STDOUT,
                               preexec_fn=_as_from_a_terminal)
    wall = time.monotonic() - t0
    return {"rep": k, "code": code, "wall_s": wall, "load_before": load_before, "load_after": loadavg(),
            "tests": outcomes(xml)}


def summarize(mode, reps):
    lines = ["# suite soak: %s, %d repetitions" % (mode, len(reps)), "",
             "| rep | wall s | load before (1/5/15 min) | load after | exit | passed | failed | error | skipped |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for r in reps:
        c = collections.Counter(o for o, _ in r["tests"].values())
        lines.append("| %d | %.0f | %s | %s | %d | %d | %d | %d | %d |" % (
            r["rep"], r["wall_s"], r["load_before"], r["load_after"], r["code"],
            c["passed"], c["failed"], c["error"], c["skipped"]))
    counts = collections.defaultdict(collections.Counter)
    first = {}
    for r in reps:
        for name, (outcome, message) in r["tests"].items():
            counts[name][outcome] += 1
            if outcome in ("failed", "error") and name not in first:
                first[name] = "rep %d: %s" % (r["rep"], message)
    unsteady = sorted(n for n, c in counts.items() if c["passed"] != len(reps))
    lines += ["", "Tests that did not pass in every repetition (%d of %d):" % (len(unsteady), len(counts)), ""]
    if unsteady:
        lines += ["| test | passed | failed | error | skipped | first failure |", "| --- | --- | --- | --- | --- | --- |"]
        for n in unsteady:
            c = counts[n]
            lines.append("| %s | %d | %d | %d | %d | %s |" % (n, c["passed"], c["failed"], c["error"], c["skipped"],
                                                           first.get(n, "").replace("|", "/")))
    else:
        lines.append("none")
    total = collections.Counter()
    for c in counts.values():
        total.update(c)
    lines += ["", "Totals over all repetitions: %d passed, %d failed, %d error, %d skipped; wall %s s" % (
        total["passed"], total["failed"], total["error"], total["skipped"],
        ", ".join("%.0f" % r["wall_s"] for r in reps))]
    return "\n".join(lines) + "\n"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--reps", type=int, default=3, help="repetitions of the suite (default 3)")
    ap.add_argument("--busy", type=int, default=0, metavar="N",
                    help="keep N CPU-bound processes running for the whole soak (default 0: the machine as it is)")
    ap.add_argument("--out", default=None, help="directory for the junit XML, logs and summary.md")
    ap.add_argument("--workers", type=int, default=3, help="pytest-xdist workers (-n), as the README's test command; 0: none")
    ap.add_argument("pytest_args", nargs="*", help="after --: passed to pytest (e.g. a subset of tests)")
    args = ap.parse_args(argv)
    mode = "busy (%d CPU-bound processes)" % args.busy if args.busy else "as the machine is (no added load)"
    out_dir = Path(args.out or REPO / "out" / ("soak-%s-%s" % ("busy%d" % args.busy if args.busy else "plain",
                                                               time.strftime("%Y%m%d-%H%M%S"))))
    out_dir.mkdir(parents=True, exist_ok=True)

    def on_term(signum, frame):
        raise SystemExit(128 + signum)

    signal.signal(signal.SIGTERM, on_term)
    signal.signal(signal.SIGHUP, on_term)
    burners = []
    reps = []
    try:
        print("soak: %s, %d repetitions, %d cores, load %s; output in %s" % (mode, args.reps, os.cpu_count(), loadavg(), out_dir),
              flush=True)
        burners = start_burners(args.busy)
        for k in range(1, args.reps + 1):
            r = run_rep(k, out_dir, args.pytest_args, args.workers)
            reps.append(r)
            c = collections.Counter(o for o, _ in r["tests"].values())
            print("rep %d: %.0f s, exit %d, %d passed, %d failed, %d error, %d skipped; load %s -> %s" % (
                k, r["wall_s"], r["code"], c["passed"], c["failed"], c["error"], c["skipped"],
                r["load_before"], r["load_after"]), flush=True)
    finally:
        stop_burners(burners)
        if reps:
            text = summarize(mode, reps)
            (out_dir / "summary.md").write_text(text)
            print()
            print(text, end="")
    failed = any(r["code"] != 0 for r in reps)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
