"""End to end against the virtual board: real micropython + firmware behind a pty, real pyserial,
real mpremote, the host CLI."""

import json
import subprocess
import sys
import time

import numpy as np
import pytest
import serial

from firmware import protocol as P
from firmware.protocol import VERSION
from host import cli
from host.link.board_client import BoardClient
from host.link.board_time import BoardTime
from host.errors import UserError
from host.link.frames import FrameDecoder
from host.link.connect import Connection
from host.link.stream import Arrays
from host.link.telemetry_log import CsvLog, load
from host.link.virtual_board import VirtualBoard

from testkit import processes as host_processes

MPREMOTE = str(__import__("pathlib").Path(sys.executable).parent / "mpremote")


@pytest.fixture(scope="module")
def vboard():
    with VirtualBoard() as board:
        yield board


def mpremote(port, *args):
    proc = subprocess.run([MPREMOTE, "connect", port, *args], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    return proc.stdout


def test_status_handshake_over_the_pty(vboard):
    with BoardClient(vboard.path) as board:
        status = board.status_info
        assert status["version"] == VERSION and status["board"] == "sim" and status["protocol"] == P.PROTOCOL_VERSION
        # the interface table's hash, computed by the real MicroPython, is CPython's
        assert status["interface"] == P.interface_hash()
        assert status["mode"] == "idle"
        from firmware.protocol import PARAMS

        assert board.call("get", "slew") == dict((r[0], r[1]) for r in PARAMS)["slew"]


def test_garbage_on_the_port_gets_error_frames_and_the_firmware_keeps_serving(vboard):
    with BoardClient(vboard.path) as board:
        board.serial.write(b"hello board\n\x00\xff\xfe garbage\n!12 status *00000000\n")
        errors = []
        deadline = time.monotonic() + 2
        while len(errors) < 3 and time.monotonic() < deadline:
            errors += [f for f in board._read_frames() if f.type == P.T_ERROR]
        assert [e.text() for e in errors] == ["expected !<seq> <cmd> <args> *<crc32>", "line is not ASCII", "checksum mismatch"]
        assert board.call("status")["board"] == "sim"


def stream_for(board, seconds, heartbeat=True):
    """Telemetry records for `seconds` of the board's own time (their t_us), heartbeating or
    not; a wall-clock limit only against a board that stops streaming."""
    clock, chunks, deadline = BoardTime(), [], time.monotonic() + 60
    while clock.seconds < seconds and time.monotonic() < deadline:
        if heartbeat:
            board.heartbeat_if_due()
        for f in board.frames():
            chunks.append(f.records().copy())
            clock.add(chunks[-1])
    return np.concatenate(chunks) if chunks else np.zeros((0, P.RECORD_WORDS), dtype=np.int32)


def test_open_loop_drive_moves_the_simulated_nut_and_stop_zeroes_duty(vboard):
    with BoardClient(vboard.path) as board:
        board.call("mode", "open_loop")
        board.call("target", 6000)
        board.start_stream(100)
        raw1 = stream_for(board, 1.0)[:, P.FIELDS.index("raw1")]
        board.call("stop")
        board.stop_stream()
        status = board.call("status")
    assert len(raw1) > 50
    assert abs(int(raw1[-1]) - int(raw1[0])) > 50  # the nut travelled (codes, 12-bit)
    assert status["mode"] == "idle" and status["duty"] == 0


def test_the_watchdog_stops_the_motor_after_a_second_of_board_time_without_the_host(vboard):
    """The host goes quiet (no command, no heartbeat) with the motor running: the firmware stops
    it once host_timeout_ms of its own steps have passed, and not before. Heartbeats keep it
    running for longer than that. Judged on the board's clock (telemetry t_us), so a loaded
    machine, where the virtual board falls behind the wall clock, changes nothing."""
    col = {name: P.FIELDS.index(name) for name in ("t_us", "duty", "faults")}
    with BoardClient(vboard.path) as board:
        timeout_ms = board.call("get", "host_timeout_ms")
        assert timeout_ms == 1000
        board.call("reset")
        time.sleep(0.1)
        board.call("mode", "open_loop")
        board.call("target", 1500)
        board.start_stream(100)  # the last command: the board's silence counts from here
        alive = stream_for(board, 2.5 * timeout_ms / 1000)  # heartbeats: runs on
        # the stream may open within the slew's ramp to 1500 (500 a step: 500, 1000) when the
        # board runs its steps in a burst on a loaded machine; from there on the duty must hold
        up = np.flatnonzero(alive[:, col["duty"]] == 1500)
        assert up.size and (alive[:up[0], col["duty"]] < 1500).all() and up[0] <= 2, alive[:5, col["duty"]]
        assert (alive[up[0]:, col["duty"]] == 1500).all() and not alive[:, col["faults"]].any()
        board.call("target", -1500)  # heard: silence from here
        quiet = stream_for(board, 2.0 * timeout_ms / 1000, heartbeat=False)
        status = board.call("status")
        board.call("stop")
        board.stop_stream()
        board.call("reset")
    heard = np.flatnonzero(quiet[:, col["duty"]] == -1500)  # records from the step after the last command
    assert heard.size
    quiet = quiet[heard[0]:]  # (earlier ones were queued while the host waited for its reply)
    t = quiet[:, col["t_us"]].astype(np.int64)
    tripped = np.flatnonzero(quiet[:, col["faults"]] != 0)
    assert tripped.size, "the motor ran on with the host silent for 2 s of board time"
    first = tripped[0]
    silent_ms = ((t[first] - t[0]) % (1 << 30)) / 1000
    assert timeout_ms - 10 <= silent_ms <= timeout_ms + 10, silent_ms  # within one 10 ms stream period
    assert (quiet[:first, col["duty"]] == -1500).all() and (quiet[first:, col["duty"]] == 0).all()
    assert status["faults"] == ["host_timeout"] and status["mode"] == "idle"
    assert "host silent for more than 1000 ms" in status["last_fault"]


def test_ten_seconds_at_1khz_with_zero_lost_frames(vboard, tmp_path):
    out = tmp_path / "run.csv"
    with Connection(vboard.path) as connection:
        with CsvLog(out, connection.client.call("status"), 1000) as csv_log, connection.tee(1000, [csv_log]) as tee:
            summary = tee.pump(10)
    data = load(out)
    t = data["t_us"]
    assert summary.lost_frames == 0 and summary.board_dropped == 0 and summary.crc_errors == 0
    # Ten seconds of the board's own time (its records' clock), whatever the machine's load
    # (a loaded virtual board drops ticks it cannot catch up and takes longer in wall time) ...
    assert len(t) == summary.samples and 10.0 <= (t[-1] - t[0]) / 1e6 < 10.5
    assert set(np.diff(t)) == {1000}  # ... and every record of every step arrived, in order


def test_one_stream_feeds_every_sink_while_a_tee_logs_the_whole_run(vboard, tmp_path):
    """Connection.stream hands each frame's records to every sink (numpy arrays, any callable),
    cut at its seconds of board time; a tee on the same connection (the CSV of host log, or of
    move --log) gets those frames too and the ones before and after, with no gap."""
    out = tmp_path / "sinks.csv"
    sizes, arrays = [], Arrays()
    with Connection(vboard.path) as connection:
        with CsvLog(out, connection.client.call("status"), 500) as csv_log, connection.tee(500, [csv_log]) as tee:
            tee.pump(0.2)
            covered = connection.stream(0.5, 500, [arrays, lambda rows: sizes.append(len(rows))])
            tee.pump(0.2)
        assert connection.link is connection.client  # the tee is off again
    run, logged = arrays.run(), load(out)
    assert 0.5 <= covered < 0.6 and 0.496 < run["t_s"][-1] <= 0.5  # the last frame cut at 0.5 s
    assert len(run["t_us"]) == sum(sizes) and set(np.diff(run["t_us"]) % (1 << 30)) == {2000}
    t = logged["t_us"]
    assert tee.summary.samples == len(t) and set(np.diff(t) % (1 << 30)) == {2000}  # no gap, whoever read
    first = int(np.flatnonzero(t == run["t_us"][0])[0])
    assert first >= 90 and (t[first:first + len(run["t_us"])] == run["t_us"]).all()
    assert len(t) - first - len(run["t_us"]) >= 90  # and the second pump's 0.2 s after


def test_cli_log_and_plot(vboard, tmp_path, capsys):
    # vboard has no calibration: both commands say once that positions and force are 0, and the
    # raw ADC codes are kept (logged, and plotted in their place).
    out = tmp_path / "cli.csv"
    assert cli.main(["log", "--port", vboard.path, "--out", str(out), "--seconds", "1", "--rate", "200"]) == 0
    printed = capsys.readouterr()
    assert "lost frames 0" in printed.out
    warnings = [line for line in printed.err.split("\n") if "warning" in line]
    assert len(warnings) == 1 and warnings[0].startswith("warning: the board has no usable calibration (")
    assert "d1_um, d2_um, defl_um, force_mN will be 0; the raw ADC codes (raw1, raw2, raw_ref) are logged" in warnings[0]
    data = load(out)
    assert 150 <= len(data["t_us"]) <= 260
    assert not data["d2_um"].any() and not data["force_mN"].any()
    assert data["raw1"].min() > 0 and data["raw2"].min() > 0 and data["raw_ref"].min() > 0
    assert cli.main(["plot", str(out), "--out", str(tmp_path / "cli.png")]) == 0
    printed = capsys.readouterr()
    assert printed.out.strip() == str(tmp_path / "cli.png")
    assert printed.err.count("\n") == 1 and printed.err.startswith("warning: %s: d1_um, d2_um, defl_um, force_mN are all 0" % out)
    assert "plotting the raw ADC codes (raw1, raw2, raw_ref) instead" in printed.err
    assert (tmp_path / "cli.png").stat().st_size > 10000


def test_mpremote_exec_fs_and_atomic_rename_then_firmware_comes_back(vboard, tmp_path):
    board_json = json.loads(mpremote(vboard.path, "exec", "print(open('board.json').read())"))
    assert board_json["name"] == "sim"
    src = tmp_path / "note.txt"
    src.write_bytes(b"\x00binary\xff\r\n" * 100)
    mpremote(vboard.path, "fs", "cp", str(src), ":note.tmp", "+", "exec", "import os; os.rename('note.tmp', 'note.txt')")
    assert (vboard.root / "note.txt").read_bytes() == src.read_bytes()
    listing = mpremote(vboard.path, "fs", "ls", ":")
    assert "note.txt" in listing and "firmware/" in listing
    # mpremote left the board at the REPL: the client soft-resets it, main.py starts the firmware.
    with BoardClient(vboard.path) as board:
        assert board.status_info["version"] == VERSION
        assert board.hellos == 1


def test_ctrl_c_stops_the_firmware_with_the_motor_off(vboard):
    with BoardClient(vboard.path) as board:
        board.call("mode", "open_loop")
        board.call("target", 8000)
        time.sleep(0.3)
        assert board.call("status")["duty"] != 0  # driving when the Ctrl-C comes
        board.serial.write(b"\x03")
        time.sleep(0.5)
    out = mpremote(vboard.path, "resume", "exec", "import boards.sim.machine as m; print(m.motor_voltage(), m.ticks)")
    assert int(out.split()[-1]) > 100  # the same process: the world that was driven
    assert float(out.split()[-2]) == 0.0


def test_ctrl_c_cause_is_readable_after_the_next_boot(vboard):
    """Ctrl-C while driving: the REPL gets control with the motor off; the soft reset that boots
    main.py again finds why the last run ended in last_exit.txt and reports it in status."""
    from firmware.app import EXIT_RUNNING

    with BoardClient(vboard.path) as board:
        board.call("mode", "open_loop")
        board.call("target", 3000)
        time.sleep(0.2)
        board.serial.write(b"\x03")
        time.sleep(0.5)
    assert (vboard.root / "last_exit.txt").read_text().startswith("interrupted: KeyboardInterrupt")
    with BoardClient(vboard.path) as board:  # at the REPL: the client soft-resets, main.py boots
        last = board.status_info["last_exit"]
    assert last.startswith("interrupted: KeyboardInterrupt (Ctrl-C) after ") and last.endswith(" steps, motor off"), last
    assert (vboard.root / "last_exit.txt").read_text() == EXIT_RUNNING  # the new run is under way


def test_client_errors_are_one_line_user_errors(vboard, tmp_path):
    with pytest.raises(UserError, match="not found"):
        BoardClient(str(tmp_path / "ttyNONE"))
    with BoardClient(vboard.path):
        with pytest.raises(UserError, match="busy"):
            BoardClient(vboard.path)
    # a port where nothing answers (a pty nobody serves) is "no lsea-kit firmware"
    import os
    import tty

    master, slave = os.openpty()
    tty.setraw(slave)
    try:
        with pytest.raises(UserError, match="no lsea-kit firmware"):
            BoardClient(os.ttyname(slave), timeout=0.2, retries=0)
    finally:
        os.close(master)
        os.close(slave)


def test_decoder_sees_the_repl_banner_as_noise(vboard):
    ser = serial.Serial(vboard.path, timeout=0.05)
    try:
        ser.write(b"\x03")  # firmware stops, REPL prints its banner and prompt
        time.sleep(0.4)
        ser.write(b"\x04")  # soft reset at the friendly REPL: the board boots main.py again
        data = b""
        end = time.monotonic() + 3
        dec = FrameDecoder()
        frames = []
        while time.monotonic() < end and not any(f.type == P.T_HELLO for f in frames):
            chunk = ser.read(4096)
            data += chunk
            frames += dec.feed(chunk)
    finally:
        ser.close()
    assert b"soft reboot" in data and b">>> " in data
    assert dec.skipped_bytes > 0 and [f.type for f in frames if f.type == P.T_HELLO] == [P.T_HELLO]


def test_version_mismatch_and_missing_calibration_are_refused(vboard, tmp_path):
    with pytest.raises(UserError, match="no usable calibration"):
        BoardClient(vboard.path, require_calibration=True)
    root = tmp_path / "flash"
    root.mkdir()
    from host.link.firmware_files import install_factory
    from host.link.virtual_board import DEFAULT_BOARD

    install_factory(root, DEFAULT_BOARD)
    protocol = root / "firmware" / "protocol.py"
    text = protocol.read_text()
    assert 'VERSION = "%s"' % VERSION in text
    protocol.write_text(text.replace('VERSION = "%s"' % VERSION, 'VERSION = "0.0.0-old"'))
    with VirtualBoard(root=root, factory=False) as old:
        with pytest.raises(UserError, match="board runs firmware 0.0.0-old, this host expects"):
            BoardClient(old.path)



def test_a_board_whose_interface_table_differs_is_refused_in_one_line(tmp_path):
    """Same version, same protocol number, one parameter's default changed in the board's copy of
    the table (a firmware from another checkout): the host names both hashes and says reflash."""
    from host.link.firmware_files import install_factory
    from host.link.virtual_board import DEFAULT_BOARD

    root = tmp_path / "flash"
    root.mkdir()
    install_factory(root, DEFAULT_BOARD)
    protocol = root / "firmware" / "protocol.py"
    text = protocol.read_text()
    assert '("slew", 500, 0, DUTY_MAX' in text
    protocol.write_text(text.replace('("slew", 500, 0, DUTY_MAX', '("slew", 400, 0, DUTY_MAX'))
    with VirtualBoard(root=root, factory=False) as other:
        with pytest.raises(UserError) as refused:
            BoardClient(other.path)
    message = str(refused.value)
    assert "\n" not in message and P.interface_hash() in message and "reflash (host flash --port" in message, message
    assert message.startswith("board's interface table ") and "is not this host's" in message, message


def test_mpremote_reset_boots_the_firmware_like_a_hard_reset(vboard):
    boots = vboard.boots
    mpremote(vboard.path, "reset")
    deadline = time.monotonic() + 5
    while vboard.boots < boots + 2 and time.monotonic() < deadline:  # mpremote's soft reset, then the reset
        time.sleep(0.05)
    time.sleep(0.5)
    with BoardClient(vboard.path, check=False) as board:  # no handshake, so no soft reset: main.py ran by itself
        assert board.request("status", retries=2)["version"] == VERSION


def test_log_ctrl_c_ends_with_a_complete_file_and_a_summary(vboard, tmp_path):
    out = tmp_path / "interrupted.csv"
    proc = host_processes.start("log", "--port", vboard.path, "--out", str(out), "--rate", "500",
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline and (not out.exists() or out.stat().st_size < 20000):
        time.sleep(0.1)
    code, stdout, _ = host_processes.stop(proc)
    assert code == 0 and "(interrupted)" in stdout and "lost frames 0" in stdout
    lines = out.read_text().splitlines()
    assert lines[0].split(",") == list(P.FIELDS)
    assert all(len(line.split(",")) == len(P.FIELDS) for line in lines[1:])  # no torn last row
    t = load(out)["t_us"]
    assert len(t) > 200 and set(np.diff(t)) == {2000}
    assert "%d samples" % len(t) in stdout
