"""A newcomer's first minutes, timed: from `git clone` to a live plot of a move on a calibrated
virtual board (issue 28's "under two minutes").

What it runs, as the README's "first minute" says, in a fresh clone of this checkout in a
temporary folder: `python -m venv .venv`, `pip install -q -e '.[sim]'`, `host sim` in the
background, `host status` (--port auto finds it), then `host move --to 40 --log run.csv --live`
with a window on an X screen (Xvfb, when it is installed; without it the move writes the PNG a
machine without a display gets). It prints the seconds to the install's end and to the move's.

The install's time depends on where pip finds its wheels (a package cache or index on this
machine is much faster than a download); the figure says which machine it was.

Call (from the repository root): python bench/bench_first_minute.py
"""

import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main():
    with tempfile.TemporaryDirectory(prefix="lsea-first-minute-") as tmp:
        start = time.monotonic()
        clone = Path(tmp) / "lsea-kit"
        subprocess.run(["git", "clone", "-q", str(ROOT), str(clone)], check=True)
        subprocess.run([sys.executable, "-m", "venv", ".venv"], cwd=clone, check=True)
        subprocess.run([".venv/bin/pip", "install", "-q", "-e", ".[sim]"], cwd=clone, check=True)
        installed = time.monotonic()
        host = str(clone / ".venv" / "bin" / "host")
        env = dict(os.environ)
        xvfb = None
        if shutil.which("Xvfb"):
            read, write = os.pipe()
            xvfb = subprocess.Popen(["Xvfb", "-displayfd", str(write), "-screen", "0", "1280x1024x24", "-nolisten", "tcp"],
                                    pass_fds=(write,), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            os.close(write)
            with os.fdopen(read) as pipe:
                env["DISPLAY"] = ":" + pipe.readline().strip()
        else:
            env.pop("DISPLAY", None)
        sim = subprocess.Popen([host, "sim"], cwd=clone, stdout=subprocess.PIPE, text=True)
        try:
            print("host sim:", sim.stdout.readline().strip())  # its device path, once the board answers
            subprocess.run([host, "status"], cwd=clone, check=True, stdout=subprocess.DEVNULL)
            subprocess.run([host, "move", "--to", "40", "--log", "run.csv", "--live"], cwd=clone, env=env, check=True)
            moved = time.monotonic()
        finally:
            sim.terminate()
            sim.wait(30)
            if xvfb is not None:
                xvfb.terminate()
                xvfb.wait(10)
        window = "a window on Xvfb" if xvfb is not None else "no display: the PNG"
        print("install done %.1f s after the clone began; the live move (%s) done at %.1f s" % (
            installed - start, window, moved - start))


if __name__ == "__main__":
    main()
