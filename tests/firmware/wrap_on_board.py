"""Every counter of the step across its wrap or saturation point on a board: the installed firmware
(board.json, calibration.json) with the board's own `machine`: its ADC, PWM and the hard timer that
runs the step in its interrupt. Run by tests/link/test_emulated_pico.py on the emulated Pico
(`mpremote run`), where the rp2 port's 31-bit small ints would turn an overflow into a heap int,
which a hard interrupt cannot allocate (a step_exception fault).

The counters are started a few steps below their limits before the timer starts; the script then
drains the telemetry ring as the link does while the interrupt steps, and prints one JSON line:
RESULT {...}. Plain MicroPython: nothing from the tests' own support is on the board.
"""

import json
import time

from firmware.app import App
from firmware.safety import SILENCE_CAP

MASK = 1073741823  # 2**30 - 1


def drain(ring, dst, out, until_ms):
    deadline = time.ticks_add(time.ticks_ms(), until_ms)
    while time.ticks_diff(deadline, time.ticks_ms()) > 0:
        while ring.read_into(dst):
            out.append(dst[0])
        time.sleep_ms(1)


def main():
    from array import array

    app = App("board.json", "calibration.json")
    c = app.ctrl
    ring = app.telemetry
    app.set_param("host_timeout_ms", 0)  # no host here: the silence count must stop by itself
    app.set_stream(app.board["loop_hz"])  # a record every step
    app.set_mode("position")  # holds the block where it is
    period = c.period_us
    c.t_us = MASK - 4 * period + 1  # wraps on the 4th step
    c.steps = MASK - 2
    ring.head = ring.tail = MASK - 5
    app.safety.silence = SILENCE_CAP - 3
    dst = array("i", [0] * 12)
    stamps = []
    app.start()  # the hard timer: the step now runs in its interrupt
    try:
        drain(ring, dst, stamps, 60)
        steps = c.steps
        # the overrun count saturates: with a 1 us period every step is an overrun
        c.overruns = MASK - 2
        c.period_us = 1
        drain(ring, dst, [], 30)
        c.period_us = period
        drain(ring, dst, [], 10)
    finally:
        app.shutdown()
    st = app.status()
    gaps = sorted(set((b - a) & MASK for a, b in zip(stamps, stamps[1:])))
    print("RESULT " + json.dumps({
        "faults": st["faults"], "timer": st["timer"], "period": period, "records": len(stamps),
        "first": stamps[:3], "gaps": gaps, "crossed": bool(stamps) and max(stamps) > MASK - 4 * period and min(stamps) < 8 * period,
        "steps_after": steps, "head": ring.head, "dropped": ring.dropped, "silence": app.safety.silence,
        "silence_cap": SILENCE_CAP, "overruns": c.overruns, "mask": MASK}))


main()
