"""Figures from the firmware on an emulated Raspberry Pi Pico: MicroPython's own rp2 port (the UF2 a
user downloads) on the rp2040js emulator, the simulated actuator on its pins (host sim --chip rp2040).

    .venv/bin/python bench/bench_emulated_pico.py --uf2 FILE [--calibration FILE] [--seconds 5]
        [--rates 1000 2000] [--stream-seconds 60] [--kills 8] [--only flash,step,memory,stream,kills]
        [--json OUT]

Every figure is read from the chip itself, by the firmware's own instruments or MicroPython's:
1. flash: `host flash` over the emulated USB serial (mpremote), onto an empty flash and again onto
   an installed one: wall seconds, emulated seconds, verified (CRCs read back, the firmware
   answers with the calibration's CRC).
2. step: status()'s step_us_max and overruns (time.ticks_us on the chip, its hard timer's IRQ)
   after --seconds of board time in each mode: idle; position, moving the block between 20 and
   40 mm; force, holding -5 N against the gauge (the friction section on, so the play operator
   runs), with the pots as BCM-3 and as tables, at each loop rate of --rates (a board file like
   boards/pico.json with that loop_hz); beside them, from the emulator, the share of the CPU's
   cycles the firmware used in that window (step, main loop, USB; the rest it slept in WFE),
   while streaming telemetry at 100 Hz. The calibrations are the simulated actuator's own,
   made from its model by the real calibration-file code (testkit/model.py), relabelled pico.
3. memory: gc.mem_free() and the largest free block (the largest bytearray that can still be
   allocated) after the firmware's boot (App and Link built as board_main builds them) with
   --calibration, a guided run's (default: the table model calibration); and how long that boot
   took on the chip (imports, board file, calibration checks and tables: time.ticks_us).
4. stream: --stream-seconds of board time of telemetry at 1 kHz over USB: records, frames lost
   (sequence gaps), records the board's ring overwrote.
5. kills: `host flash` of a new calibration killed (its whole process group: host and mpremote)
   at --kills instants spread over its duration; after each, the board is reset and must boot
   and answer with the old or the new calibration.

Emulated, not measured: the RP2040's timing is rp2040js's cycle model of the Cortex-M0+ (no XIP
flash cache misses, no wait states), so the microseconds are a lower bound of a real Pico's.
"""

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from host.errors import UserError
from host.link.emulated_pico.board import EmulatedPico
from host.link.flashing import flash, mpremote

REPO = Path(__file__).resolve().parent.parent
CLOCK_HZ = 125_000_000  # the RP2040's clk_sys under MicroPython (machine.freq())

MEMORY_SCRIPT = """\
import gc, time
gc.collect()
t0 = time.ticks_us()
from firmware.app import App
from firmware.link import Link
app = App("board.json", "calibration.json")
link = Link(app)
boot_us = time.ticks_diff(time.ticks_us(), t0)
gc.collect()
free = gc.mem_free()
lo, hi = 0, free
while hi - lo > 16:
    mid = (lo + hi) // 2
    try:
        b = bytearray(mid)
        b = None
        lo = mid
    except MemoryError:
        hi = mid
print("MEM", free, lo, gc.mem_alloc(), boot_us)
"""


def pico_board(tmp, loop_hz):
    """boards/pico.json with `loop_hz`, as a file in `tmp`."""
    board = json.loads((REPO / "boards" / "pico.json").read_text())
    board["loop_hz"] = loop_hz
    path = Path(tmp) / ("pico-%d.json" % loop_hz)
    path.write_text(json.dumps(board, indent=1))
    return path


def model_calibration(tmp, pots):
    """The simulated actuator's calibration (testkit/model.py), pots "bcm3" or "pwl", for board pico."""
    from testkit import model

    board = dict(model.sim_board(), name="pico")
    path = Path(tmp) / ("model-%s.json" % pots)
    model.write_model_calibration(path, board=board, pots=pots)
    return path


def timed_flash(pico, board_path, calibration):
    t0 = time.monotonic()
    s0 = pico.state()["t_s"]
    status = flash(pico.path, str(board_path), str(calibration) if calibration else None, progress=lambda m: None,
                   ask_board=False)
    return {"wall_s": round(time.monotonic() - t0, 2), "emulated_s": round(pico.state()["t_s"] - s0, 2),
            "calibration_crc": status.get("calibration_crc"), "verified": True}


def step_figures(pico, seconds, mode):
    """step_us_max and overruns after `seconds` of board time in `mode`, from a fresh boot."""
    from host.api import Board
    from host.link.board_time import BoardTime

    with Board(pico.path) as board:
        client = board.client
        client.soft_reset(wait=10)
        client.handshake()
        if mode == "force":
            pico.rig({"load": {"kind": "gauge", "side": "high"}, "reference": "pot2"})
            client.call("mode", "force")
            client.call("target", -5000)
        elif mode == "position":
            client.call("mode", "position")
        clock = BoardTime()
        client.start_stream(100)
        before = pico.state()
        flip = 0
        try:
            while clock.seconds < seconds:
                client.heartbeat_if_due()
                for frame in client.frames(timeout=0.05):
                    clock.stamps(frame.records())
                if mode == "position" and clock.seconds >= flip:
                    client.call("target", 20000 if int(flip) % 2 == 0 else 40000)
                    flip += 1.0
        finally:
            client.stop_stream()
        after = pico.state()
        status = client.call("status")
        client.call("stop")
        if mode == "force":
            pico.rig({"load": {"kind": "none"}})
    busy = (after["cycles"] - before["cycles"]) / ((after["t_s"] - before["t_s"]) * CLOCK_HZ)
    return {"step_us_max": status["step_us_max"], "overruns": status["overruns"], "steps": status["steps"],
            "period_us": status["period_us"], "timer": status["timer"], "faults": status["faults"],
            "cpu_busy_pct": round(100 * busy, 1)}


def memory_figures(pico):
    out = mpremote(pico.path, ["exec", MEMORY_SCRIPT], timeout=300)
    line = [x for x in out.splitlines() if x.startswith("MEM ")][-1]
    free, largest, alloc, boot_us = (int(v) for v in line.split()[1:])
    return {"mem_free": free, "largest_free_block": largest, "mem_alloc": alloc, "boot_ms": round(boot_us / 1000, 1)}


def stream_figures(pico, seconds):
    from host.api import Board
    from host.link.board_time import BoardTime

    t0 = time.monotonic()
    with Board(pico.path) as board:
        client = board.client
        clock = BoardTime()
        records = 0
        client.start_stream(1000)
        try:
            while clock.seconds < seconds:
                client.heartbeat_if_due()
                for frame in client.frames(timeout=0.05):
                    rows = frame.records()
                    clock.stamps(rows)
                    records += len(rows)
        finally:
            client.stop_stream()
        dec = client.decoder
        return {"board_seconds": round(clock.seconds, 3), "records": records, "lost_frames": dec.lost_frames,
                "crc_errors": dec.crc_errors, "ring_dropped": dec.board_dropped,
                "wall_s": round(time.monotonic() - t0, 1)}


def kill_figures(pico, board_path, old_cal, new_cal, kills):
    """`host flash --calibration new_cal` killed at `kills` instants; each time the board must boot
    with old_cal's or new_cal's CRC (and with the new one only once "verifying" was printed)."""
    from host.link.board_client import BoardClient

    crcs = {json.loads(Path(p).read_text())["crc32"]: name for name, p in (("old", old_cal), ("new", new_cal))}
    cmd = [sys.executable, "-m", "host", "flash", "--port", pico.path, "--board", str(board_path),
           "--calibration", str(new_cal)]
    flash(pico.path, str(board_path), str(old_cal), progress=lambda m: None, ask_board=False)
    t0 = time.monotonic()
    subprocess.run(cmd, check=True, capture_output=True, cwd=REPO)
    whole = time.monotonic() - t0
    rows = []
    for i in range(kills):
        flash(pico.path, str(board_path), str(old_cal), progress=lambda m: None, ask_board=False)
        at = whole * (i + 0.5) / kills
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, cwd=REPO, start_new_session=True,
                                text=True)
        time.sleep(at)
        os.killpg(proc.pid, signal.SIGKILL)
        printed = proc.communicate()[0]
        with BoardClient(pico.path, check=False) as client:
            booted = client.soft_reset(wait=10)
            status = client.handshake()
        got = crcs.get(status.get("calibration_crc"), "neither")
        allowed = {"old"} if "installing" not in printed else ({"new"} if "verifying" in printed else {"old", "new"})
        rows.append({"killed_at_s": round(at, 2), "booted": booted, "calibration": got, "expected": sorted(allowed),
                     "ok": booted and got in allowed})
    return {"flash_s": round(whole, 2), "kills": rows, "all_ok": all(r["ok"] for r in rows)}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--uf2", default=os.environ.get("LSEA_PICO_UF2"), help="MicroPython for RPI_PICO (default $LSEA_PICO_UF2)")
    ap.add_argument("--calibration", default=None, help="a guided run's calibration for the memory figure (board pico)")
    ap.add_argument("--seconds", type=float, default=5.0, help="board seconds per mode for the step figures")
    ap.add_argument("--rates", type=int, nargs="+", default=[1000, 2000], help="loop rates, Hz")
    ap.add_argument("--stream-seconds", type=float, default=60.0)
    ap.add_argument("--kills", type=int, default=8)
    ap.add_argument("--only", default="flash,step,memory,stream,kills")
    ap.add_argument("--json", default=None, help="write the figures here too")
    args = ap.parse_args()
    parts = set(args.only.split(","))
    out = {"uf2": args.uf2, "date": time.strftime("%Y-%m-%d"), "machine": os.uname().machine}
    with tempfile.TemporaryDirectory(prefix="bench-pico-") as tmp, EmulatedPico(uf2=args.uf2) as pico:
        boards = {hz: pico_board(tmp, hz) for hz in args.rates}
        cals = {pots: model_calibration(tmp, pots) for pots in ("bcm3", "pwl")}
        first = boards[args.rates[0]]
        if "flash" in parts:
            out["flash"] = {"empty": timed_flash(pico, first, cals["pwl"]), "installed": timed_flash(pico, first, cals["pwl"])}
            print("flash", json.dumps(out["flash"]), flush=True)
        if "step" in parts:
            out["step"] = []
            for hz in args.rates:
                for pots in ("bcm3", "pwl"):
                    flash(pico.path, str(boards[hz]), str(cals[pots]), progress=lambda m: None, ask_board=False)
                    for mode in ("idle", "position", "force"):
                        row = dict(loop_hz=hz, pots=pots, mode=mode, **step_figures(pico, args.seconds, mode))
                        out["step"].append(row)
                        print("step", json.dumps(row), flush=True)
        if "memory" in parts:
            cal = Path(args.calibration) if args.calibration else cals["pwl"]
            flash(pico.path, str(first), str(cal), progress=lambda m: None, ask_board=False)
            out["memory"] = dict(calibration=str(cal), **memory_figures(pico))
            print("memory", json.dumps(out["memory"]), flush=True)
        if "stream" in parts:
            flash(pico.path, str(first), str(cals["pwl"]), progress=lambda m: None, ask_board=False)
            out["stream"] = stream_figures(pico, args.stream_seconds)
            print("stream", json.dumps(out["stream"]), flush=True)
        if "kills" in parts and args.kills:
            out["kills"] = kill_figures(pico, first, cals["bcm3"], cals["pwl"], args.kills)
            print("kills", json.dumps(out["kills"]), flush=True)
        out["emulator"] = pico.state()
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except UserError as exc:
        sys.exit("error: %s" % exc)
