"""The link on a busy computer: slow is not silent.

A 2-core machine kept busy on purpose (CPU-bound processes beside the virtual board and the
client): flashing, commands, a closed-loop move and a 200 Hz stream still work and lose no
frame. A board frozen for a while (SIGSTOP on the virtual board's interpreter: what a starved
process looks like from the host) answers once it runs again, within the client's patience; a
board frozen for good is reported as "the board stopped answering", not as a traceback.
"""

import os
import signal
import subprocess
import sys
import threading
import time

import pytest

from host.link.board_client import BoardClient
from host.link.connect import Connection
from host.link.flashing import flash
from host.link.virtual_board import VirtualBoard


BURNERS = 3  # with the board, the client and the suite's other worker: a load of 5-6 on 2 cores


@pytest.fixture
def busy_machine():
    procs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(BURNERS)]
    try:
        yield
    finally:
        for p in procs:
            p.kill()
            p.wait()


def test_flash_commands_moves_and_streams_survive_a_busy_machine(busy_machine, model_calibration):
    with VirtualBoard() as vb:
        status = flash(vb.path, "sim", model_calibration, progress=lambda s: None)
        assert status["calibration_crc"] is not None
    with Connection("sim", calibration=model_calibration) as connection:
        board = connection.client
        for _ in range(20):
            assert board.call("status")["faults"] == []
        from host.guided.acquire import settle

        ok, value, _ = settle(board, "position", 20000, "d2_um", 200, timeout_s=10.0)
        board.call("stop")
        assert ok, value
        lost = board.decoder.lost_frames
        board.start_stream(200)
        records = 0
        t0 = time.monotonic()
        while time.monotonic() - t0 < 3.0:
            board.heartbeat_if_due()
            records += sum(len(f.records()) for f in board.frames(timeout=0.05))
        board.stop_stream()
        assert records > 200 and board.decoder.lost_frames == lost, (records, board.decoder.lost_frames - lost)


def _interpreter(vb):
    return vb._child.pid


def test_a_frozen_board_that_comes_back_is_slow_not_gone(model_calibration):
    with VirtualBoard(calibration=model_calibration) as vb:
        client = BoardClient(vb.path)
        try:
            pid = _interpreter(vb)
            os.kill(pid, signal.SIGSTOP)
            threading.Timer(3.0, os.kill, (pid, signal.SIGCONT)).start()
            t0 = time.monotonic()
            status = client.request("status")  # resent until the board runs again
            assert status["faults"] == [] and time.monotonic() - t0 >= 2.5
        finally:
            client.close()


def test_a_board_frozen_for_good_is_said_to_have_stopped_answering(model_calibration):
    with VirtualBoard(calibration=model_calibration) as vb:
        client = BoardClient(vb.path, patience=2.0)
        pid = _interpreter(vb)
        try:
            os.kill(pid, signal.SIGSTOP)
            with pytest.raises(TimeoutError, match="the board stopped answering: no reply to status .* nothing else came"):
                client.request("status")
        finally:
            os.kill(pid, signal.SIGCONT)
            client.close()


def test_random_bytes_on_the_port_are_not_blamed_on_a_busy_computer():
    """Something else writing to the port (random bytes, no frame of ours): the request gives up
    saying what came was not our frames, not that the board or the computer is overloaded."""
    import random

    master, slave = os.openpty()
    stop = threading.Event()

    def noise():
        rng = random.Random(1)
        while not stop.is_set():
            os.write(master, bytes(rng.randrange(256) for _ in range(64)))
            time.sleep(0.005)

    writer = threading.Thread(target=noise, daemon=True)
    writer.start()
    client = BoardClient(os.ttyname(slave), check=False, patience=1.0)
    try:
        with pytest.raises(TimeoutError, match="mostly not lsea-kit frames .*another program on the port"):
            client.request("status")
    finally:
        stop.set()
        writer.join(1)
        client.close()
        os.close(master)
        os.close(slave)
