"""Run code under the real MicroPython unix port, with the repository importable.

Firmware modules are imported as `firmware.<name>` on both interpreters, so the same test case
can run under CPython (in-process) and MicroPython (a subprocess via `run_micropython`).
"""

import os
import shutil
import json
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def micropython_executable():
    """The `micropython` binary installed by the test dependencies (next to this Python first)."""
    beside = Path(sys.executable).parent / "micropython"
    if beside.exists():
        return str(beside)
    found = shutil.which("micropython")
    if not found:
        raise RuntimeError("micropython not found: install the test extras (pip install -e '.[test]')")
    return found


def micropython_env(extra_paths=()):
    env = dict(os.environ)
    env["MICROPYPATH"] = ":".join([".frozen", *map(str, extra_paths), str(REPO)])
    return env


def run_micropython(source, *, extra_paths=(), timeout=120, check=True, args=()):
    """Run `source` (program text) under MicroPython; return the CompletedProcess (text mode)."""
    proc = subprocess.run(
        [micropython_executable(), "-X", "heapsize=8M", "-c", source, *args],
        cwd=str(REPO),
        env=micropython_env(extra_paths),
        capture_output=True,
        text=True,
        timeout=timeout,
    )
    if check and proc.returncode != 0:
        raise AssertionError(
            "micropython exited %d\n--- stdout\n%s\n--- stderr\n%s"
            % (proc.returncode, proc.stdout, proc.stderr)
        )
    return proc


def run_case(module, call, timeout=120):
    """Evaluate `module.call` (e.g. "case_x(1, 2)") under the real MicroPython with tests/ on
    its path; the case returns something JSON-able, printed last. Returns it, parsed."""
    proc = run_micropython(
        "import json, %s\nprint(json.dumps(%s.%s))\n" % (module, module, call),
        extra_paths=[REPO / "tests"], timeout=timeout,
    )
    return json.loads(proc.stdout.strip().splitlines()[-1])
