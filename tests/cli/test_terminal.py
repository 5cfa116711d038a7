"""Terminal manners: progress rewrites its line only on a terminal, results go to stdout, and a
closed pipe ends a command quietly."""

import io
import subprocess
import sys

from host import terminal
from testkit.interpreters import REPO


class FakeTTY(io.StringIO):
    def isatty(self):
        return True


def test_progress_rewrites_on_a_terminal_and_writes_lines_elsewhere(monkeypatch):
    tty = FakeTTY()
    monkeypatch.setattr(sys, "stderr", tty)
    terminal.progress_line("step 1")
    terminal.progress_line("step 2")
    terminal.end_progress()
    assert tty.getvalue().startswith("\rstep 1") and tty.getvalue().endswith("\n") and tty.getvalue().count("\n") == 1
    log = io.StringIO()
    monkeypatch.setattr(sys, "stderr", log)
    terminal.progress_line("step 1")
    terminal.progress_line("step 2")
    for i in range(50):  # a fast stream of updates: at most one a second in a file
        terminal.progress_line("%d samples" % i, every=1.0)
    terminal.end_progress()
    lines = log.getvalue().splitlines()
    assert "\r" not in log.getvalue() and lines[:2] == ["step 1", "step 2"] and len(lines) <= 4, lines


def _host(*args, **kw):
    return subprocess.run([sys.executable, "-m", "host", *args], cwd=REPO, capture_output=True, text=True, timeout=300, **kw)


def test_demo_prints_progress_on_stderr_and_the_result_on_stdout(tmp_path):
    proc = _host("demo", "--out", str(tmp_path / "demo"))
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip().splitlines() == ["report: %s" % (tmp_path / "demo" / "report.md")], proc.stdout
    assert "[1/4]" in proc.stderr and "\r" not in proc.stderr


def test_a_closed_pipe_ends_a_command_quietly():
    """`host status | head -3` when head has gone: no BrokenPipeError traceback, no 'Exception
    ignored' at exit; the reader is closed here before the command writes anything."""
    for args in (["--help"], ["fit", "examples/sweep_60mm.csv"]):
        p = subprocess.Popen([sys.executable, "-m", "host", *args], cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        p.stdout.close()
        err = p.stderr.read().decode()
        code = p.wait(timeout=300)
        assert "Traceback" not in err and "BrokenPipe" not in err and "Exception ignored" not in err, err
        assert code in (0, 141), (args, code, err)


def test_quiet_leaves_only_the_result(tmp_path):
    for args in (["demo", "--quiet", "--out", str(tmp_path / "a")], ["--quiet", "demo", "--out", str(tmp_path / "b")]):
        proc = _host(*args)
        assert proc.returncode == 0 and proc.stderr == "", proc.stderr
        assert proc.stdout.strip().startswith("report: "), proc.stdout


def test_quiet_silences_progress_never_a_warning(tmp_path):
    """A log of a board without calibration warns that the positions will be 0: through --quiet
    (only progress goes), on stderr, one line; stdout keeps the result."""
    proc = _host("log", "--port", "sim", "--uncalibrated", "--out", str(tmp_path / "run.csv"), "--seconds", "0.3",
                 "--quiet")
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr.startswith("warning: the board has no usable calibration") and proc.stderr.count("\n") == 1, \
        proc.stderr
    assert "warning" not in proc.stdout and "run.csv" in proc.stdout, proc.stdout


def test_warn_ends_an_open_progress_line(monkeypatch):
    tty = FakeTTY()
    monkeypatch.setattr(sys, "stderr", tty)
    terminal.set_quiet(True)
    try:
        terminal.progress_line("step 1")  # silenced
        terminal.warn("something to know")
    finally:
        terminal.set_quiet(False)
    assert tty.getvalue() == "warning: something to know\n"


def test_commands_write_only_through_the_terminal_module():
    """One output channel: a command's results go through host.terminal.output, its progress,
    warnings and errors through note/progress_line/warn/error, never a bare print (which would
    ignore --quiet or end up on the wrong stream)."""
    import ast
    from pathlib import Path

    root = Path(__file__).resolve().parents[2] / "host"
    offenders = []
    for path in sorted((root / "commands").glob("*.py")) + [root / "cli.py"]:
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "print":
                offenders.append("%s:%d" % (path.relative_to(root.parent), node.lineno))
    assert not offenders, offenders
