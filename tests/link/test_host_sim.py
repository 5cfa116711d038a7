"""`host sim` as a process (its port answers; Ctrl-C, SIGTERM and SIGHUP end it with its board's
micropython and temporary flash gone) and `--port sim` (a throwaway board for one command)."""

import json
import subprocess

import pytest

from firmware.protocol import VERSION
from host import cli
from host.link.board_client import BoardClient
from testkit import processes as host_processes


def test_host_sim_prints_a_port_that_answers_and_stops_on_ctrl_c():
    proc = host_processes.start("sim", stdout=subprocess.PIPE, text=True)
    try:
        path = proc.stdout.readline().strip()
        assert path.startswith("/dev/pts/")
        with BoardClient(path) as board:
            assert board.status_info["board"] == "sim"
    finally:
        code, _, _ = host_processes.stop(proc)  # a deadline: a loaded machine may take seconds
    assert code == 0


def processes_mentioning(text):
    """pids whose command line contains `text` (the virtual board's micropython names its root)."""
    found = []
    for cmdline in __import__("pathlib").Path("/proc").glob("[0-9]*/cmdline"):
        try:
            if text.encode() in cmdline.read_bytes():
                found.append(int(cmdline.parent.name))
        except OSError:
            pass
    return found


@pytest.mark.parametrize("stop_signal", ["SIGTERM", "SIGHUP"])
def test_host_sim_cleans_up_on_sigterm_and_sighup_as_on_ctrl_c(stop_signal):
    import signal
    from pathlib import Path

    proc = host_processes.start("sim", "--load", "gauge@25", stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        path = proc.stdout.readline().strip()
        root = str(host_processes.sim_root(proc))
        assert path.startswith("/dev/pts/") and Path(root).name.startswith("lsea-vboard-")
        assert json.loads((Path(root) / "rig.json").read_text())["load"] == {"kind": "gauge", "side": "high", "anchor_mm": 25.0}
        with BoardClient(path) as board:
            assert board.status_info["board"] == "sim"
        assert processes_mentioning(root)  # its micropython runs
    finally:
        code, _, _ = host_processes.stop(proc, getattr(signal, stop_signal))
    assert code == 0
    assert not Path(root).exists()  # the temporary flash directory is gone ...
    assert processes_mentioning(root) == []  # ... and so is micropython


def test_port_sim_runs_a_command_on_a_throwaway_board(capsys):
    assert cli.main(["status", "--port", "sim"]) == 0
    out = capsys.readouterr().out
    assert "%-30s %s" % ("firmware version", VERSION) in out and "%-30s sim" % "board" in out
