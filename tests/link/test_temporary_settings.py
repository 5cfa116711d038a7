"""What a host command changes for itself comes back by itself when the host goes away: the
stroke limits a sweep opens and the gains a tuning run tries are temporary values (`set NAME
VALUE temp`), which the firmware puts back once the host has been silent for host_timeout_ms,
with the motor off too; and a calibration waiting for a person holds nothing open. The real
unix port, firmware, pty and pyserial, through the host CLI and its client."""

import select
import signal
import subprocess
import time


from host.link.board_client import BoardClient
from host.link.virtual_board import VirtualBoard

from testkit import processes as host_processes

WRAP = 1 << 30  # the status field `steps` counts modulo 2**30


def test_temporary_values_come_back_after_a_timeout_of_board_time_without_the_host(model_calibration):
    """Judged on the board's own step count, so load cannot make it pass or fail: every look at
    the board is itself a word from the host, so between two looks either fewer steps than the
    timeout passed, or the temporary values must be back."""
    with VirtualBoard(calibration=model_calibration) as vb, BoardClient(vb.path) as board:
        boot = board.call("status")["stroke_um"]
        timeout_steps = board.call("get", "host_timeout_ms")  # at the sim board's 1 kHz
        board.call("set", "stroke_min_um", -65535, "temp")
        board.call("set", "stroke_max_um", 65535, "temp")
        board.call("set", "kp_pos", 900)  # for good: it stays
        st = board.call("status")
        assert st["params_temporary"] == ["stroke_min_um", "stroke_max_um"] and st["stroke_um"] == [-65535, 65535], st
        for _ in range(40):
            last = st["steps"]
            time.sleep(1.5)
            st = board.call("status")
            if not st["params_temporary"]:
                break
            assert (st["steps"] - last) % WRAP < timeout_steps + 50, ("a whole timeout of silence, nothing back", st)
        assert st["params_temporary"] == [] and st["stroke_um"] == boot, st
        assert "stroke_min_um" in st["params_restored"] and "temporary" in st["params_restored"], st
        assert board.call("get", "kp_pos") == 900 and st["mode"] == "idle" and st["faults"] == []


def _read_until(proc, text, timeout_s=120):
    """Everything the child wrote to stdout until `text` appeared (a prompt has no newline)."""
    seen = b""
    deadline = time.monotonic() + timeout_s
    while text.encode() not in seen:
        left = deadline - time.monotonic()
        assert left > 0 and proc.poll() is None, seen.decode(errors="replace")[-2000:]
        ready, _, _ = select.select([proc.stdout], [], [], min(left, 1.0))
        if ready:
            chunk = proc.stdout.read1(4096)
            assert chunk, seen.decode(errors="replace")[-2000:]
            seen += chunk
    return seen.decode(errors="replace")


def test_a_calibration_killed_while_a_person_reads_the_gauge_leaves_the_stroke_limits_closed(model_calibration, tmp_path):
    """`host calibrate pots --reference manual` opens the stroke limits only around each
    motion: killed (SIGKILL, or a closed terminal) at a dial-gauge prompt, the board's limits
    are already the ones in force before, and nothing temporary is left."""
    with VirtualBoard(calibration=model_calibration) as vb:
        with BoardClient(vb.path) as board:
            before = board.call("status")["stroke_um"]
        proc = host_processes.start("calibrate", "pots", "--port", vb.path, "--reference", "manual",
                                    "--out", str(tmp_path / "cal.json"), "--no-flash",
                                    stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
        try:
            _read_until(proc, "Press Enter")  # mount the dial gauge
            proc.stdin.write(b"\n")
            proc.stdin.flush()
            _read_until(proc, "Dial gauge reading at stop 1")  # after the drive to the end stop
            proc.stdin.write(b"0.5\n")
            proc.stdin.flush()
            _read_until(proc, "Dial gauge reading at stop 2")  # after a pulse
            proc.send_signal(signal.SIGKILL)
            proc.wait(timeout=30)
        finally:
            host_processes.kill(proc)
        with BoardClient(vb.path) as board:
            st = board.call("status")
        assert st["stroke_um"] == before and st["params_temporary"] == [], st
        assert st["mode"] == "idle" and st["params_changed"] == [], st


def test_a_sweep_and_a_tuning_run_change_the_board_only_temporarily(model_calibration):
    """What the board holds while a sweep's stroke limits are open and while a tuning trial runs:
    temporary values, the ones the firmware restores by itself; after each, nothing."""
    from host.guided import acquire
    from host.guided.tuning import tune

    class Watching:
        """The client, asking the board which values are temporary whenever a step starts."""

        def __init__(self, board):
            self.board = board
            self.seen = []

        def call(self, name, *args, **kw):
            if name == "target" and not self.seen:
                self.seen.append(self.board.call("status")["params_temporary"])
            return self.board.call(name, *args, **kw)

        def __getattr__(self, name):
            return getattr(self.board, name)

    with VirtualBoard(calibration=model_calibration) as vb, BoardClient(vb.path) as board:
        before = board.call("status")["stroke_um"]
        with acquire.open_stroke(board):
            st = board.call("status")
            assert st["params_temporary"] == ["stroke_min_um", "stroke_max_um", "stop_margin_um"] and st["stroke_um"] == [-65535, 65535], st
        st = board.call("status")
        assert st["params_temporary"] == [] and st["stroke_um"] == before, st
        watching = Watching(board)
        tune(watching, "position", 25000, 2000, 0.3, 50, grid={"kp_pos": [700], "ki_pos": [20]})
        assert watching.seen == [["kp_pos", "ki_pos"]], watching.seen
        st = board.call("status")
        assert st["params_temporary"] == [] and (board.call("get", "kp_pos"), board.call("get", "ki_pos")) != (700, 20)
