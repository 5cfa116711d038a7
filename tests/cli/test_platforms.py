"""The host CLI where POSIX-only modules are missing (Windows): every command builds and the
board-free ones run; only the virtual board, which needs a pseudo-terminal, says in one line
that it cannot run there. Simulated by refusing fcntl, termios, tty and pty to our own packages
(pyserial keeps its own platform choice)."""

import subprocess
import sys

import pytest

from testkit.interpreters import REPO

GUARD = """
import sys, builtins
real = builtins.__import__
def guard(name, globals=None, *a, **k):
    importer = (globals or {}).get("__name__", "")
    if name.split(".")[0] in ("fcntl", "termios", "tty", "pty") and importer.split(".")[0] in ("host", "boards", "firmware"):
        raise ImportError("No module named %r (simulated Windows)" % name)
    return real(name, globals, *a, **k)
builtins.__import__ = guard
from host import cli
sys.exit(cli.main(sys.argv[1:]))
"""


def _host(*args):
    return subprocess.run([sys.executable, "-c", GUARD, *args], cwd=REPO, capture_output=True, text=True, timeout=300)


@pytest.mark.parametrize("args", [["--help"], ["fit", "examples/sweep_60mm.csv"], ["flash", "--help"], ["log", "--help"],
                                  ["move", "--help"], ["status", "--help"], ["compare", "--help"], ["demo", "--help"]])
def test_commands_run_without_posix_modules(args):
    proc = _host(*args)
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr


def test_board_free_commands_do_their_work_and_board_commands_reach_the_port(tmp_path):
    """Not only --help: compare and demo write their files, and status, move and log open the
    serial port (here a missing one: the one error line a real user would get)."""
    proc = _host("compare", "examples/sweep_60mm.csv", "--orders", "2-3", "--models", "bcm,pwl", "--out", str(tmp_path / "cmp"), "-q")
    assert proc.returncode == 0 and list((tmp_path / "cmp").glob("*.png")), proc.stderr
    proc = _host("demo", "--out", str(tmp_path / "demo"), "-q")
    assert proc.returncode == 0 and (tmp_path / "demo" / "report.md").exists(), proc.stderr
    for args in (["status"], ["move", "--to", "30"], ["log", "--out", str(tmp_path / "run.csv")]):
        proc = _host(*args, "--port", str(tmp_path / "ttyNONE"))
        err = proc.stderr.strip().splitlines()
        assert proc.returncode == 2 and len(err) == 1 and "not found" in err[0], (args, proc.stderr)


def test_the_virtual_board_says_in_one_line_where_it_cannot_run():
    proc = _host("status", "--port", "sim")
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: the virtual board") and "pseudo-terminal" in lines[0], proc.stderr


def test_a_missing_tool_names_the_install_command_for_this_kind_of_install(monkeypatch, tmp_path):
    import host.errors as errors

    assert errors.install_hint("sim") == "pip install -e '%s[sim]'" % REPO  # this checkout, from anywhere
    monkeypatch.setattr(errors, "__file__", str(tmp_path / "site-packages" / "host" / "errors.py"))
    monkeypatch.setattr(errors, "_installed_from", lambda: None)  # from an index or a wheel
    assert errors.install_hint("sim") == "pip install 'lsea-kit[sim]'"
    assert errors.install_hint() == "pip install 'lsea-kit'"
    monkeypatch.setattr(errors, "_installed_from", lambda: "/home/me/lsea-kit")  # pip install /home/me/lsea-kit
    assert errors.install_hint("sim") == "pip install '/home/me/lsea-kit[sim]'"


def test_where_pip_installed_from_is_read_from_its_record(monkeypatch):
    """PEP 610's direct_url.json as pip writes it for a local directory, an editable checkout
    and an index (no record)."""
    import json
    from importlib import metadata

    import host.errors as errors

    class Dist:
        def __init__(self, record):
            self.record = record

        def read_text(self, name):
            return None if self.record is None else json.dumps(self.record)

    for record, expected in (({"dir_info": {}, "url": "file:///tmp/lsea%20kit"}, "/tmp/lsea kit"),
                             ({"dir_info": {"editable": True}, "url": "file:///work/lsea-kit"}, "/work/lsea-kit"),
                             ({"archive_info": {}, "url": "file:///tmp/lsea_kit-0.1.0-py3-none-any.whl"}, None),
                             (None, None)):
        monkeypatch.setattr(metadata, "distribution", lambda name, r=record: Dist(r))
        assert errors._installed_from() == expected, record
