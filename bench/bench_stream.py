"""Sustained telemetry over the virtual board's pty: the real firmware with the simulated physics
on the MicroPython unix port, read by pyserial (target: 1 kHz for 60 s with zero lost frames).

    .venv/bin/python bench/bench_stream.py [--seconds 60] [--rate 1000 ...]

For each rate: streams for the given time and reports records/s received, lost frames (sequence
gaps), records the board's ring overwrote, missing steps (gaps in the records' step clock), and,
read back from the simulated machine after stopping the firmware (mpremote resume exec), the
timer ticks the unix port had to skip because the loop fell behind real time.
"""

import argparse
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from host.link.board_client import BoardClient
from host.link.virtual_board import VirtualBoard

MPREMOTE = str(Path(sys.executable).parent / "mpremote")


def measure(rate, seconds):
    with VirtualBoard() as vb:
        with BoardClient(vb.path) as board:
            loop_hz = 1000
            board.start_stream(rate)
            t_us = []
            t0 = time.monotonic()
            dropped = 0
            while time.monotonic() - t0 < seconds:
                board.heartbeat_if_due()
                for f in board.frames(timeout=0.05):
                    t_us.append(f.records()[:, 0].copy())
                    dropped = f.dropped()
            wall = time.monotonic() - t0
            lost = board.decoder.lost_frames
            crc = board.decoder.crc_errors
            board.serial.write(b"\x03")  # stop the firmware; the REPL keeps the sim module state
            time.sleep(0.3)
        out = subprocess.run([MPREMOTE, "connect", vb.path, "resume", "exec",
                              "import boards.sim.machine as m; print(m.ticks, m.skipped_ticks)"],
                             capture_output=True, text=True, timeout=30).stdout.split()
        ticks, skipped = (int(out[-2]), int(out[-1])) if len(out) >= 2 else (-1, -1)
    t = np.concatenate(t_us) if t_us else np.zeros(0, dtype=np.int64)
    step_us = 1000000 // loop_hz * (loop_hz // rate)
    missing = int(np.sum(np.diff(t) // step_us - 1)) if len(t) > 1 else 0
    return {"rate": rate, "records": len(t), "per_s": len(t) / wall, "lost_frames": lost, "ring_drops": dropped,
            "missing_steps": missing, "crc_errors": crc, "ticks": ticks, "skipped_ticks": skipped}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--rate", type=int, nargs="*", default=[1000])
    args = ap.parse_args()
    print("virtual board (micropython unix port + boards/sim physics), %.0f s per rate" % args.seconds)
    for rate in args.rate:
        r = measure(rate, args.seconds)
        print("rate %4d Hz: %7d records, %7.1f/s, lost frames %d, ring drops %d, missing steps %d, CRC errors %d, "
              "timer ticks %d (skipped %d)" % (r["rate"], r["records"], r["per_s"], r["lost_frames"], r["ring_drops"],
                                              r["missing_steps"], r["crc_errors"], r["ticks"], r["skipped_ticks"]))


if __name__ == "__main__":
    main()
