"""`--port auto` and `host ports`: the choosing rule on made-up port lists (USB ports are hardware
that cannot exist here), and the probe and the automatic choice against a virtual board."""

import pytest

from host import cli
from host.link import ports
from host.errors import UserError

PICO = ("/dev/ttyACM0", 0x2E8A, 0x0005, "Board in FS mode")
CP210X = ("/dev/ttyUSB0", 0x10C4, 0xEA60, "CP2102 USB to UART Bridge Controller")
MOUSE = ("/dev/ttyS0", None, None, "n/a")
CIRCUITPY_PICO = ("/dev/ttyACM1", 0x239A, 0x80F4, "Pico - CircuitPython CDC control")


def test_known_boards_are_labelled_and_others_are_not():
    assert "RP2040" in ports.label(0x2E8A, 0x0005)
    assert "CircuitPython" in ports.label(0x239A, 0x80F4)  # the Pico running CircuitPython
    assert "pyboard" in ports.label(0xF055, 0x9800)
    assert "CP210x" in ports.label(0x10C4, 0xEA60)
    assert ports.label(0x046D, 0xC077) is None and ports.label(None, None) is None


def test_auto_picks_the_only_board_and_names_the_candidates_otherwise():
    assert ports.choose([MOUSE, PICO]) == "/dev/ttyACM0"
    assert ports.choose([MOUSE, CIRCUITPY_PICO]) == "/dev/ttyACM1"  # a Pico with CircuitPython too
    with pytest.raises(UserError, match="no board found .*ttyS0"):
        ports.choose([MOUSE])
    with pytest.raises(UserError, match="2 boards found .*ttyACM0.*ttyUSB0"):
        ports.choose([PICO, CP210X, MOUSE])
    assert ports.resolve("sim") == "sim" and ports.resolve("/dev/ttyX") == "/dev/ttyX"


def test_host_ports_lists_each_port_with_what_is_on_it(monkeypatch, capsys):
    monkeypatch.setattr(ports, "list_ports", lambda: [PICO, CP210X, MOUSE])
    assert cli.main(["ports"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert len(out) == 3 and "2e8a:0005" in out[0] and "RP2040" in out[0] and "not a board we know" in out[2]


def test_port_auto_and_the_probe_find_a_board_running_our_firmware(monkeypatch, capsys):
    """A virtual board stands in for a Pico on USB: listed with the RP2040's ids, `host status`
    with no --port talks to it, and `host ports --probe` says lsea-kit answers there."""
    from host.link.virtual_board import VirtualBoard

    with VirtualBoard() as vb:
        monkeypatch.setattr(ports, "list_ports", lambda: [(vb.path, 0x2E8A, 0x0005, "Board in FS mode"), MOUSE])
        assert cli.main(["status", "--json"]) == 0
        assert '"board": "sim"' in capsys.readouterr().out
        assert cli.main(["ports", "--probe"]) == 0
        out = capsys.readouterr().out.splitlines()
        assert "lsea-kit" in out[0] and "on sim" in out[0], out


def test_a_running_host_sim_is_listed_and_found_by_port_auto(tmp_path, monkeypatch, capsys):
    """`host sim` in another terminal: `host ports` lists its pty as a virtual board and
    `--port auto` talks to it (the error used to suggest --port sim, a second, empty board);
    once it stops, it is gone from both."""
    import json
    import os
    import subprocess

    from testkit import processes

    monkeypatch.setenv("XDG_RUNTIME_DIR", str(tmp_path))  # this test's own records, not another test's
    proc = processes.start("sim", stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                           env=dict(os.environ, XDG_RUNTIME_DIR=str(tmp_path)))
    try:
        path = proc.stdout.readline().strip()
        processes.sim_root(proc)  # it says it runs (on stderr) once it is registered
        assert cli.main(["ports", "--json"]) == 0
        rows = json.loads(capsys.readouterr().out)
        assert [r["board"] for r in rows if r["device"] == path] == ["lsea-kit virtual board (host sim)"]
        assert cli.main(["status", "--json"]) == 0  # --port auto
        assert json.loads(capsys.readouterr().out)["board"] == "sim"
    finally:
        processes.stop(proc)
    assert cli.main(["ports", "--json"]) == 0
    assert path not in [r["device"] for r in json.loads(capsys.readouterr().out)]


def test_a_guided_session_on_a_host_sims_pty_mounts_its_rig(tmp_path, monkeypatch):
    """`host calibrate --port <host sim's pty>` drives the virtual rig as `--port sim` does (it
    stopped at the force step, asking for a person): the session finds the running board's
    flash, the rig's instructions reach it, its gauge is read, and closing leaves it running."""
    import json
    import os
    import subprocess

    from host.guided.prompts import Prompter
    from host.guided.rig import Rig
    from host.guided.session import Session
    from testkit import processes

    monkeypatch.setenv("XDG_RUNTIME_DIR", str(tmp_path))
    proc = processes.start("sim", stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                           env=dict(os.environ, XDG_RUNTIME_DIR=str(tmp_path)))
    try:
        path = proc.stdout.readline().strip()
        root = processes.sim_root(proc)
        with Session(path, say=lambda *_: None) as session:
            assert session.virtual is not None and session.simulated and session.root == root
            rig = Rig(Prompter(yes=True, out=lambda *_: None), session.virtual)
            rig.mount_reference("pot2")
            assert json.loads((root / "rig.json").read_text())["reference"] == "pot2"
            rig.hook_gauge(25.0, "high")
            assert isinstance(rig.gauge_reading_n(beat=session.client.heartbeat_if_due), float)
            rig.no_load()
        assert proc.poll() is None and root.is_dir()  # still running, its flash untouched
    finally:
        processes.stop(proc)
