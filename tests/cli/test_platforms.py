"""The host CLI where POSIX-only modules are missing (Windows): every command builds and the
board-free ones run; only the virtual board, which needs a pseudo-terminal, says in one line
that it cannot run there. Simulated by refusing fcntl, termios, tty and pty to our own packages
(pyserial keeps its own platform choice). And the advice for a port that will not open, in each
platform's words (COM ports and the Device Manager on Windows, the dialout group on Linux)."""

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


# pyserial's own messages for a port that would not open, as each platform words them
PYSERIAL_SAYS = {
    ("linux", "missing"): "[Errno 2] could not open port /dev/ttyACM0: [Errno 2] No such file or directory: '/dev/ttyACM0'",
    ("linux", "denied"): "[Errno 13] could not open port /dev/ttyACM0: [Errno 13] Permission denied: '/dev/ttyACM0'",
    ("linux", "busy"): "[Errno 11] Could not exclusively lock port /dev/ttyACM0: [Errno 11] Resource temporarily unavailable",
    ("darwin", "missing"): "[Errno 2] could not open port /dev/cu.usbmodem1101: [Errno 2] No such file or directory: "
                           "'/dev/cu.usbmodem1101'",
    ("darwin", "busy"): "[Errno 16] could not open port /dev/cu.usbmodem1101: [Errno 16] Resource busy: '/dev/cu.usbmodem1101'",
    ("win32", "missing"): "could not open port 'COM7': FileNotFoundError(2, 'The system cannot find the file specified.', "
                          "None, 2)",
    ("win32", "busy"): "could not open port 'COM3': PermissionError(13, 'Access is denied.', None, 5)",  # held elsewhere
}
LINUX_WORDS = ("dialout", "/dev/tty", "fuser", "lsof", "usermod")


@pytest.mark.parametrize("platform, problem", sorted(PYSERIAL_SAYS))
def test_a_port_that_will_not_open_gets_advice_in_its_platforms_words(platform, problem):
    from host.link.port_advice import open_failure, problem_of

    text = PYSERIAL_SAYS[platform, problem]
    port = {"linux": "/dev/ttyACM0", "darwin": "/dev/cu.usbmodem1101", "win32": "COM3"}[platform]
    said = open_failure(port, text, platform)
    assert "\n" not in said and port in said, said
    wanted = {"missing": "not found (is the board plugged in?", "denied": "no permission to open serial port",
              "busy": "is busy: close the other program using"}[problem]
    assert wanted in said, said
    if platform == "win32":  # COM ports, the Device Manager, no Linux tools, no virtual board (it needs WSL)
        assert not any(word in said for word in LINUX_WORDS) and "host sim" not in said, said
        assert ("Device Manager" in said) == (problem == "missing"), said
        assert problem != "busy" or ("Thonny" in said and "one program at a time" in said), said
        assert problem_of(text) == {"missing": "missing", "busy": "denied"}[problem]  # Windows' words, read as Windows means them
    elif platform == "darwin":
        assert "dialout" not in said and "fuser" not in said and "Device Manager" not in said, said
        assert problem != "busy" or "`lsof /dev/cu.usbmodem1101`" in said, said
        assert problem != "missing" or "/dev/cu.usbmodem*" in said, said
    else:
        assert "Device Manager" not in said and "COM" not in said, said
        assert problem != "denied" or "dialout group" in said, said
        assert problem != "busy" or "`fuser /dev/ttyACM0`" in said, said
        assert problem != "missing" or "/dev/ttyACM0" in said, said


@pytest.mark.parametrize("platform, example", [("linux", "/dev/ttyACM0"), ("darwin", "/dev/cu.usbmodem1101"),
                                               ("win32", "COM3")])
def test_no_board_found_names_a_port_as_its_platform_does(platform, example):
    from host.link.port_advice import advice

    said = advice("none found", "none", platform)
    assert said.startswith("no board found (serial ports: none): plug it in") and "e.g. %s" % example in said, said
    assert ("host sim" in said) == (platform != "win32"), said  # a virtual board needs a pseudo-terminal


@pytest.mark.parametrize("platform", ["linux", "darwin", "win32"])
def test_a_machine_with_no_serial_ports_is_told_what_works_on_its_platform(platform):
    from host.link.port_advice import advice

    said = advice("no ports", None, platform)
    assert said.startswith("no serial ports (plug the board in"), said
    assert ("host sim" in said and "--port sim" in said) == (platform != "win32"), said
    assert ("Device Manager" in said) == (platform == "win32"), said


def test_host_ports_with_no_ports_says_so(monkeypatch, capsys):
    from host import cli
    from host.link import ports

    monkeypatch.setattr(ports, "list_ports", lambda: [])
    assert cli.main(["ports"]) == 0
    assert capsys.readouterr().out.startswith("no serial ports (plug the board in")


def test_a_port_held_by_another_program_is_busy_on_this_machine():
    """A real pyserial refusal here: a port (a pseudo-terminal) held open exclusively, as Thonny
    or another host command would hold a board's port, is reported busy with this platform's advice."""
    import os

    import serial

    from host.errors import UserError
    from host.link.board_client import BoardClient
    from host.link.port_advice import advice

    if not hasattr(os, "openpty"):
        pytest.skip("no pseudo-terminals on this platform")
    master, slave = os.openpty()
    path = os.ttyname(slave)
    held = serial.Serial(path, 115200, exclusive=True)
    try:
        with pytest.raises(UserError) as refused:
            BoardClient(path, check=False)
        assert str(refused.value) == advice("busy", path)
    finally:
        held.close()
        os.close(master)
        os.close(slave)
