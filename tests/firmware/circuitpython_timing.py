"""Run ON a CircuitPython board with the firmware installed (bench/bench_circuitpython.py sends it
with `mpremote run`): what the step costs in each mode and allocates, what a pass of the main
loop and a garbage collection cost, and the period the paced loop really keeps. Prints one line,
RESULT <json>.

Clock: time.monotonic_ns, which counts in 30.5 us ticks on the RP2040 port and allocates, so
costs are taken over many calls; the paced loop's periods are read from it at every step."""

import gc
import json
import time
from array import array

from firmware.app import App
from firmware.hal import console_stream
from firmware.link import Link

N_COST = 200  # calls per timed mode
N_PACED = 1000  # steps of the paced loop recorded


def _us():
    return time.monotonic_ns() // 1000


app = App("board.json", "calibration.json")
link = Link(app, *console_stream())
app.set_param("host_timeout_ms", 0)  # no host sends heartbeats here
out = {"loop_hz": app.board["loop_hz"], "calibrated": app.calibration is not None, "cost_us": {}}
d2 = app.ctrl.meas.d2 if app.ctrl.meas is not None else 30000
modes = [("idle", 0), ("open_loop", 1500)]
if app.calibration is not None:
    modes += [("position", d2 + 5000), ("force", -2000)]
out["alloc_bytes_per_step"] = {}
for mode, target in modes:
    app.set_mode(mode)
    app.set_target(target)
    step = app.step
    gc.collect()
    t0 = _us()
    k = 0
    while k < N_COST:
        step(None)
        k += 1
    out["cost_us"][mode] = (_us() - t0) / N_COST
    gc.collect()
    gc.disable()
    before = gc.mem_alloc()
    k = 0
    while k < N_COST:
        step(None)
        k += 1
    out["alloc_bytes_per_step"][mode] = (gc.mem_alloc() - before) / N_COST
    gc.enable()
t0 = _us()
gc.collect()
out["collect_us"] = _us() - t0  # one collection with the firmware's live heap
app.set_mode("idle")
gc.collect()
t0 = _us()
k = 0
while k < N_COST:
    link.poll()
    app.watch_host()
    k += 1
out["cost_us"]["main_loop_pass"] = (_us() - t0) / N_COST

# the paced loop as App.run runs it, in position mode, a step's real start recorded each time
if app.calibration is not None:
    app.set_mode("position")
    app.set_target(d2)
times = array("i", [0] * N_PACED)
count = [0]
inner = app.step


def recorded(timer):
    i = count[0]
    if i < N_PACED:
        times[i] = _us() & 0x3FFFFFFF
    inner(timer)
    count[0] = i + 1
    if i + 1 >= N_PACED:
        app._quit = True


app.step = recorded
gc.collect()
free_before = gc.mem_free()
app.run(link)
gaps = [(times[i] - times[i - 1]) & 0x3FFFFFFF for i in range(1, N_PACED)]
mean = sum(gaps) / len(gaps)
out["paced"] = {"steps": N_PACED, "mean_us": mean, "sd_us": (sum((g - mean) ** 2 for g in gaps) / len(gaps)) ** 0.5,
                "min_us": min(gaps), "max_us": max(gaps), "over_1_5_periods": sum(1 for g in gaps if g * 2 >= 3 * app.ctrl.period_us),
                "overruns": app.ctrl.overruns, "step_us_max": app.ctrl.step_us_max}
out["mem_free"] = free_before
print("RESULT " + json.dumps(out))
