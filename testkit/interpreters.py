"""Run code under CPython and the real MicroPython unix port: the one runner for both.

A case is a function in a module that both interpreters import by the same dotted name (the
repository is on both paths), called with plain data and returning something JSON-able:
`both(module, call)` evaluates `module.call` here and in a MicroPython subprocess and returns both
results, `same(module, call)` also asserts they are equal, bit for bit (testkit/exact.py).
A program is text that prints its result with `testkit.exact.emit`: `programs(source)` runs it
under both interpreters (CPython in a subprocess too, for a fresh process each time).
`evaluate_on_micropython` runs a firmware function over many inputs in one process;
`run_micropython(source)` is the plain subprocess underneath.
"""

import importlib
import os
import shutil
import subprocess
import sys
from pathlib import Path

from testkit import exact

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


# micropython -c puts '' (the working directory, the repository) first on sys.path; a program that
# starts with this drops it, so that a package on extra_paths (e.g. .mpy files) shadows the
# repository's firmware/
PREFER_EXTRA_PATHS = "import sys\nif '' in sys.path:\n    sys.path.remove('')\n"


def evaluate_on_micropython(module, func, cases, inputs, extra_paths=()):
    """[[func(x, array('i', k)) for x in inputs] for k in cases] of firmware.<module>.<func>,
    computed by ONE micropython process (many constant sets over many inputs)."""
    source = PREFER_EXTRA_PATHS + (
        "from array import array\n"
        "from firmware.%s import %s as f\n"
        "X = %r\n"
        "for k in %r:\n"
        "    k = array('i', k)\n"
        "    print(' '.join([str(f(x, k)) for x in X]))\n" % (module, func, [int(x) for x in inputs], [list(map(int, k)) for k in cases])
    )
    out = run_micropython(source, extra_paths=extra_paths).stdout.split("\n")
    return [[int(v) for v in line.split()] for line in out[: len(cases)]]


def case_source(module, call):
    """Program text that prints the result of `module.call`."""
    return "import %s\nfrom testkit.exact import emit\nemit(%s.%s)\n" % (module, module, call)


def on_micropython(module, call, timeout=120, extra_paths=()):
    """The result of `module.call` (e.g. "case_x(1, 2)") under MicroPython, decoded. A package
    on `extra_paths` shadows the repository's of the same name (PREFER_EXTRA_PATHS)."""
    source = (PREFER_EXTRA_PATHS if extra_paths else "") + case_source(module, call)
    return exact.result(run_micropython(source, timeout=timeout, extra_paths=extra_paths).stdout)


def on_cpython(module, call):
    """The result of `module.call` evaluated in this process, as MicroPython's would arrive."""
    return exact.plain(eval("m." + call, {"m": importlib.import_module(module)}))


def both(module, call, timeout=120):
    """(CPython's result, MicroPython's result) of `module.call`."""
    return on_cpython(module, call), on_micropython(module, call, timeout=timeout)


def same(module, call, timeout=120):
    """The result of `module.call`, asserted identical on both interpreters."""
    here, there = both(module, call, timeout=timeout)
    assert here == there, "CPython and MicroPython disagree:\n%s\n%s" % (here, there)
    return here


def program_on_cpython(source, timeout=120):
    proc = subprocess.run([sys.executable, "-c", source], cwd=str(REPO), capture_output=True, text=True,
                          timeout=timeout)
    assert proc.returncode == 0, proc.stderr
    return exact.result(proc.stdout)


def programs(source, timeout=120):
    """(CPython's result, MicroPython's result) of a program that emits one."""
    return program_on_cpython(source, timeout), exact.result(run_micropython(source, timeout=timeout).stdout)
