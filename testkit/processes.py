"""Host commands run as child processes: to the end (`run`), or by tests that signal them
(Ctrl-C, SIGTERM, SIGHUP: `start`, `stop`).

A shell that starts the suite in the background (`nohup ... &`, no job control) starts it with
SIGINT ignored, and children inherit that: Python then installs no KeyboardInterrupt handler, and
a Ctrl-C test would wait for a child that never hears it. `start` gives each child the default
SIGINT (as in a terminal) and its own process group, and `stop` kills the whole group when the
child does not end in time, so a failing test leaves no virtual board running to load the next.
"""

import os
import signal
import subprocess
import sys


REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def run(*args, timeout=600):
    """`host ARGS` as a user runs it, to the end: (exit status, stdout, stderr)."""
    proc = subprocess.run([sys.executable, "-m", "host", *args], capture_output=True, text=True, cwd=REPO,
                          timeout=timeout)
    return proc.returncode, proc.stdout, proc.stderr


def _terminal_like():
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def start(*args, **kw):
    """Popen of `python -m host ARGS` with the default SIGINT, in a new process group."""
    return subprocess.Popen([sys.executable, "-m", "host", *args], preexec_fn=_terminal_like, start_new_session=True, **kw)


def sim_root(proc):
    """The flash directory of a `host sim` started with stderr=PIPE, from the line that says it
    runs (on stderr: stdout carries only the device path)."""
    from pathlib import Path

    for line in proc.stderr:
        if "(flash in " in line:
            return Path(line.split("(flash in ")[1].split(")")[0])
    raise AssertionError("host sim ended without saying where its flash is")


def stop(proc, sig=signal.SIGINT, timeout=60):
    """Send `sig`, wait up to `timeout` s; returns (returncode, stdout, stderr) as communicate()
    gives them. If the child is still running then, its group is killed and TimeoutExpired raised."""
    proc.send_signal(sig)
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        kill(proc)
        raise
    return proc.returncode, out, err


def kill(proc):
    """SIGKILL the child's whole process group (its micropython too) and reap it."""
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except OSError:
        pass
    proc.communicate()
