"""The virtual board's serial port behaves like a board's REPL for the tools people use with
boards: text lines end in \\r\\n, Ctrl-C interrupts, Ctrl-D soft-resets into main.py, the raw REPL
and its raw-paste mode work (Thonny and mpremote send code that way), and rshell and mpremote's
REPL drive it. The real unix port, firmware, pty, pyserial, mpremote and rshell."""

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import serial

from firmware.protocol import VERSION
from host.link.board_client import BoardClient
from host.link.virtual_board import VirtualBoard

BIN = Path(sys.executable).parent
DEADLINE_S = 30  # only spent when a test fails


@pytest.fixture(scope="module")
def vboard():
    with VirtualBoard() as board:
        yield board


def read_until(port, marker, what="output"):
    """Bytes from `port` (pyserial or a pty fd) up to and including `marker`."""
    data = b""
    deadline = time.monotonic() + DEADLINE_S
    while not data.endswith(marker):
        assert time.monotonic() < deadline, "no %r in %s: %r" % (marker, what, data[-300:])
        if isinstance(port, int):
            try:
                data += os.read(port, 1)
            except BlockingIOError:
                time.sleep(0.01)
        else:
            data += port.read(1)
    return data


def to_friendly_repl(ser):
    ser.write(b"\r\x03\x03\r\x02")  # stop whatever runs; leave a raw REPL for the friendly one
    read_until(ser, b'Type "help()" for more information.\r\n>>> ')
    time.sleep(0.2)
    ser.reset_input_buffer()


def test_the_friendly_repl_ends_lines_with_crlf_and_ctrl_c_interrupts(vboard):
    with serial.Serial(vboard.path, 115200, timeout=0.1) as ser:
        to_friendly_repl(ser)
        ser.write(b"print('one\\ntwo')\r")
        assert read_until(ser, b">>> ").endswith(b"\r\none\r\ntwo\r\n>>> ")
        ser.write(b"while True: pass\r\r")
        time.sleep(0.3)
        ser.write(b"\x03")
        out = read_until(ser, b">>> ")
        assert b"KeyboardInterrupt: \r\n" in out and b"\n" not in out.replace(b"\r\n", b"")


def test_ctrl_d_at_the_repl_soft_resets_into_the_firmware(vboard):
    with serial.Serial(vboard.path, 115200, timeout=0.1) as ser:
        to_friendly_repl(ser)
        ser.write(b"\x04")
        read_until(ser, b"MPY: soft reboot\r\n")
    with BoardClient(vboard.path, check=False) as board:  # no handshake, so no soft reset: main.py ran by itself
        assert board.request("status", retries=2)["version"] == VERSION


def test_ctrl_z_and_ctrl_backslash_are_plain_bytes_as_on_a_board(vboard):
    """On the unix port's terminal they would stop or quit micropython; on a board they are
    bytes like any other, which the firmware refuses as a bad line."""
    with BoardClient(vboard.path) as board:
        board.call("status")  # a board started just now (this file run alone) says hello first
        boots, hellos = vboard.boots, board.hellos
        board.serial.write(b"\x1a\x1c\n")
        time.sleep(0.3)
        assert board.call("status")["version"] == VERSION
        assert vboard.boots == boots and board.hellos == hellos  # no reboot, no second hello


def test_raw_paste_mode_runs_a_long_program_thonny_style(vboard):
    """mpremote's transport speaks the raw REPL the way Thonny does: raw-paste mode, with the
    board's flow control, and falls back to plain raw mode if the board refuses it."""
    from mpremote.transport_serial import SerialTransport

    program = "\n".join("x%d = %d" % (i, i) for i in range(300)) + "\nprint(x299 + x1)\nprint('a\\nb')\n"
    assert len(program) > 2000  # many windows of the board's flow control
    transport = SerialTransport(vboard.path, baudrate=115200)
    try:
        transport.enter_raw_repl(soft_reset=False)
        out = transport.exec(program)
        assert transport.use_raw_paste  # the board accepted raw-paste (else mpremote falls back)
        assert out == b"300\r\na\r\nb\r\n"
        transport.exit_raw_repl()
    finally:
        transport.close()


def test_mpremote_repl_shows_lines_without_staircase(vboard):
    """`mpremote repl` on a terminal: the board's output reaches the screen as sent (mpremote sets
    the terminal raw), so each line must end in \\r\\n or the next starts where it ended."""
    master, slave = os.openpty()
    proc = subprocess.Popen([str(BIN / "mpremote"), "connect", vboard.path, "repl"], stdin=slave, stdout=slave,
                            stderr=slave, start_new_session=True)
    os.close(slave)
    os.set_blocking(master, False)
    try:
        read_until(master, b"Use Ctrl-] or Ctrl-x to exit this shell\r\n", "mpremote's banner")
        os.write(master, b"\x03")
        read_until(master, b">>> ", "the prompt after Ctrl-C")
        os.write(master, b"for i in range(3): print('line', i)\r\r")
        out = read_until(master, b"line 2\r\n>>> ", "the loop's output")
        assert b"line 0\r\nline 1\r\nline 2\r\n>>> " in out
        os.write(master, b"\x1d")  # Ctrl-]: leave mpremote
        proc.wait(timeout=DEADLINE_S)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        os.close(master)


def rshell(port, *command):
    proc = subprocess.run([str(BIN / "rshell"), "-p", port, "--quiet", *command], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0 and "Traceback" not in proc.stderr + proc.stdout, proc.stdout + proc.stderr
    return proc.stdout


def test_rshell_lists_and_reads_the_board_files_and_the_firmware_comes_back(vboard):
    listing = rshell(vboard.path, "ls", "/pyboard")  # interrupts the firmware (Ctrl-C), as on a board
    assert {"board.json", "main.py", "firmware/"} <= set(listing.split())
    board_json = rshell(vboard.path, "cat", "/pyboard/board.json")
    assert board_json.strip() == (vboard.root / "board.json").read_text().strip()
    with BoardClient(vboard.path) as board:  # at the REPL: soft reset, main.py starts the firmware
        assert board.status_info["version"] == VERSION


def test_a_raw_repl_boot_that_dies_before_its_prompt_boots_into_the_raw_repl_again(monkeypatch):
    """mpremote soft-resets in the raw REPL, then reads the pty (without a timeout) until the raw
    REPL's banner. If the process booting for it dies before its prompt (killed here right after
    it starts; a Ctrl-C that reached it during its start does the same), the relay must boot the
    raw REPL again, not main.py, whose firmware never prints that banner: mpremote would wait
    for good (a reflash's 120 s "no answer")."""
    original = VirtualBoard._spawn
    killed = []

    def spawn_and_kill_the_first_raw_boot(self, run_main):
        original(self, run_main)
        if not run_main and not killed:
            killed.append(self._child.pid)
            self._child.send_signal(signal.SIGKILL)

    monkeypatch.setattr(VirtualBoard, "_spawn", spawn_and_kill_the_first_raw_boot)
    with VirtualBoard() as board:
        try:
            out = subprocess.run([str(BIN / "mpremote"), "connect", board.path, "exec", "print('ran', 6 * 7)"],
                                 capture_output=True, text=True, timeout=DEADLINE_S)
        except subprocess.TimeoutExpired:
            pytest.fail("mpremote got no answer in %d s after a raw-REPL boot died" % DEADLINE_S)
    assert killed, "no raw-REPL boot happened"
    assert out.returncode == 0 and "ran 42" in out.stdout, out


def test_input_sent_faster_than_the_repl_reads_it_never_stalls_the_relay(vboard):
    """A host may send more than the board reads for a while (a paste into a busy REPL). The relay
    must keep carrying the board's output meanwhile: a relay that blocks writing into the
    process's full input, while the process blocks writing its echo into the relay's full output,
    hangs both for good (a board's USB port never deadlocks that way)."""
    import threading

    lines = 40000  # each echoed with its result and a prompt: far more than a pty buffers either way
    payload = b"1\r" * lines + b"print('done', 6 * 7)\r"
    with serial.Serial(vboard.path, 115200, timeout=0.1) as ser:
        to_friendly_repl(ser)
        ser.write(b"import time; time.sleep(1)\r")  # busy: nothing is read while the paste arrives
        writer = threading.Thread(target=ser.write, args=(payload,), daemon=True)
        writer.start()
        out, deadline = b"", time.monotonic() + DEADLINE_S
        while not out.endswith(b"done 42\r\n>>> "):
            assert time.monotonic() < deadline, "the relay stalled: %r" % out[-200:]
            out += ser.read(65536)
        writer.join(timeout=DEADLINE_S)
        assert not writer.is_alive()
    assert out.count(b"1\r\n1\r\n>>> ") > lines // 2  # echoed and answered, not dropped


@pytest.mark.filterwarnings("ignore::pytest.PytestUnhandledThreadExceptionWarning")  # the relay's end, raised on purpose
def test_a_silent_virtual_board_says_what_its_processes_and_relay_did(monkeypatch):
    """When mpremote gets no answer, the error names the virtual board's recent process exits and
    why its relay stopped, if it did: an exception there once ended the relay without a word."""
    from host.link.flashing import BoardSilent, mpremote

    with VirtualBoard() as board:
        with BoardClient(board.path) as client:
            client.call("status")
        board._child.send_signal(signal.SIGKILL)  # a process that dies: the relay boots another
        deadline = time.monotonic() + DEADLINE_S
        while board.boots < 2:
            assert time.monotonic() < deadline, "no reboot after the process was killed"
            time.sleep(0.05)
        assert re.fullmatch(r"boot 1 \(main\.py\) exited with -9 after [0-9.]+ s", board.exits[0]), board.exits

        def broken(data):
            raise RuntimeError("broken on purpose")

        monkeypatch.setattr(board, "_from_child", broken)
        with pytest.raises(BoardSilent) as silent:
            mpremote(board.path, ["exec", "print(1)"], timeout=5)
        assert "boot 1 (main.py) exited with -9" in str(silent.value)
        assert "the relay stopped: RuntimeError: broken on purpose" in str(silent.value)


def test_input_a_process_had_not_read_dies_with_it_as_a_reset_loses_it():
    """What the relay still holds for a process that resets is not fed to the next one: it would
    start reading from the middle of a line (found by a review: 2,167 lines of a paste ran after
    a machine.reset(), the first a SyntaxError)."""
    import threading

    with VirtualBoard(factory=False) as board:  # no main.py: every boot ends at a friendly REPL
        with serial.Serial(board.path, 115200, timeout=0.1) as ser:
            read_until(ser, b">>> ", "the first boot's prompt")
            payload = b"import time, machine; time.sleep(1.5); machine.reset()\r" + b"".join(
                b"print('LEAK%05d')\r" % i for i in range(3000))
            writer = threading.Thread(target=ser.write, args=(payload,), daemon=True)
            writer.start()
            out = read_until(ser, b"MPY: soft reboot\r\n", "the reset")
            out += read_until(ser, b">>> ", "the next boot's prompt")
            time.sleep(1.0)
            out += ser.read(65536)
            writer.join(timeout=DEADLINE_S)
    after = out.split(b"MPY: soft reboot")[-1]
    assert b"LEAK" not in after and b"Error" not in after, after[:300]
