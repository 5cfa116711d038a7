"""Figures from the firmware on an emulated Raspberry Pi Pico running CircuitPython: its plain build
(host/link/plain_firmware.py) through analogio and pwmio, the step paced by the main loop, on the
rp2040js emulator with the simulated actuator on its pins.

    .venv/bin/python bench/bench_circuitpython.py --uf2 FILE [--rates 250 500] [--oversample N] [--json OUT]

For each loop rate: boards/pico_circuitpython.json with that loop_hz (and `oversample` reads per
channel a step, when given), installed by `host flash`
(plain source, through the raw REPL) with the simulated actuator's model calibration (testkit/model.py,
tables, Df, force, friction), then tests/firmware/circuitpython_timing.py run on the chip with
`mpremote run`, which measures with the chip's own clock (time.monotonic_ns):
- the step's cost in each mode (idle, open loop, position, force; 200 calls each) and what it
  allocates (gc.mem_alloc over 200 calls with the collector off);
- a pass of the main loop without the step (the link's poll and the host watchdog);
- one garbage collection with the firmware's heap;
- the paced loop as App.run runs it, in position mode: 1000 step start times, the periods between
  them (mean, standard deviation, extremes, how many were 1.5 periods or longer) and the step's
  own overrun count and longest step.
Also the boot: how long importing (CircuitPython compiles the source) and building the App took.

Emulated, not measured on a Pico: rp2040js's cycle model of the Cortex-M0+ at 125 MHz (no flash
cache misses), so the microseconds are a lower bound of a real Pico's.
"""

import argparse
import json
import os
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

TIMING = os.path.join(ROOT, "tests", "firmware", "circuitpython_timing.py")
BOOT = ("import time, gc\nt0 = time.monotonic_ns()\nimport firmware.app\nt1 = time.monotonic_ns()\n"
        "app = firmware.app.App('board.json', 'calibration.json')\nt2 = time.monotonic_ns()\n"
        "print('BOOT', (t1 - t0) // 1000, (t2 - t1) // 1000, gc.mem_free(), app.calibration is not None)\n")


def measure(uf2, rate, tmp, oversample=None):
    from host.link.emulated_pico.board import EmulatedPico
    from host.link.flashing import flash, mpremote, to_repl
    from testkit import model

    board = json.load(open(os.path.join(ROOT, "boards", "pico_circuitpython.json")))
    board["loop_hz"] = rate
    if oversample:
        board["oversample"] = oversample
    board_path = os.path.join(tmp, "pico_circuitpython.json")
    with open(board_path, "w") as f:
        json.dump(board, f)
    cal = os.path.join(tmp, "calibration.json")
    model.write_model_calibration(cal, board=dict(model.sim_board(), name=board["name"]))
    with EmulatedPico(uf2=uf2, board=board_path) as pico:
        t0 = time.monotonic()
        status = flash(pico.path, board_path, cal, ask_board=False)
        flash_s = time.monotonic() - t0
        to_repl(pico.path)
        boot = [line.split()[1:] for line in mpremote(pico.path, ["exec", BOOT], timeout=600).splitlines()
                if line.startswith("BOOT ")][0]
        to_repl(pico.path)
        out = mpremote(pico.path, ["run", TIMING], timeout=1800)
        result = json.loads([line for line in out.splitlines() if line.startswith("RESULT ")][-1][len("RESULT "):])
    result.update(flash_wall_s=round(flash_s, 1), calibration_crc=status.get("calibration_crc"),
                  import_us=int(boot[0]), app_us=int(boot[1]), mem_free_after_boot=int(boot[2]))
    return result


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--uf2", default=os.environ.get("LSEA_CIRCUITPY_UF2"),
                    help="CircuitPython for raspberry_pi_pico (.uf2); default $LSEA_CIRCUITPY_UF2")
    ap.add_argument("--rates", type=int, nargs="+", default=[250, 500], help="loop rates to run, Hz")
    ap.add_argument("--oversample", type=int, help="reads per channel a step (default: the board file's)")
    ap.add_argument("--json", help="write every figure to this file")
    a = ap.parse_args()
    if not a.uf2:
        sys.exit("give the CircuitPython UF2 with --uf2 FILE (or $LSEA_CIRCUITPY_UF2)")
    rows = {}
    with tempfile.TemporaryDirectory() as tmp:
        for rate in a.rates:
            print("loop %d Hz: flashing and measuring on the emulated Pico..." % rate, file=sys.stderr, flush=True)
            rows[rate] = r = measure(a.uf2, rate, tmp, a.oversample)
            c, al, p = r["cost_us"], r["alloc_bytes_per_step"], r["paced"]
            print("loop %d Hz (period %d us), %s reads a channel a step" % (rate, 1000000 // rate, a.oversample or "the board file's"))
            print("  step cost us: " + ", ".join("%s %.0f" % (m, c[m]) for m in ("idle", "open_loop", "position", "force")))
            print("  step allocates bytes: " + ", ".join("%s %.0f" % (m, al[m]) for m in ("idle", "open_loop", "position", "force")))
            print("  main-loop pass without the step %.0f us; one garbage collection %d us" % (c["main_loop_pass"], r["collect_us"]))
            print("  paced loop, position mode, %d steps: period mean %.0f us, sd %.0f, %d-%d; >= 1.5 periods %d; "
                  "overruns %d; longest step %d us" % (p["steps"], p["mean_us"], p["sd_us"], p["min_us"], p["max_us"],
                                                        p["over_1_5_periods"], p["overruns"], p["step_us_max"]))
            print("  boot: import (compile) %.1f s, App %.1f s, %d bytes free after; host flash %.0f s wall"
                  % (r["import_us"] / 1e6, r["app_us"] / 1e6, r["mem_free_after_boot"], r["flash_wall_s"]), flush=True)
    if a.json:
        with open(a.json, "w") as f:
            json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
