"""Every counter of the step at its wrap or saturation point, run under CPython, the MicroPython
unix port and the emulated Cortex-M0 (tests/firmware/test_wrap.py).

A board runs for months: 2**30 us of t_us is 18 minutes, 2**30 steps 12.4 days at 1 kHz. Each
case starts the counters a few steps below their limits and runs the step across them with the
heap locked. On the 32-bit M0 (31-bit small ints) any intermediate that left 31 bits would be a
heap int, so a MemoryError would latch step_exception; the unix port's 63-bit ints cannot show
that, which is why the same case also runs on the emulated chip.
"""

from array import array

from testkit.replay import load, replay_app, run_steps

try:
    import micropython
except ImportError:
    micropython = None

MASK = 1073741823  # 2**30 - 1: every counter lives in [0, MASK]


def _locked(step, n):
    lock = micropython is not None and hasattr(micropython, "heap_lock")
    if lock:
        micropython.heap_lock()
    try:
        run_steps(step, n)
    finally:
        if lock:
            micropython.heap_unlock()


def case_counters_wrap(path, board_path="boards/sim.json", mode="force", target=3000):
    from firmware.safety import SILENCE_CAP

    app, _ = replay_app(load(path), board_path=board_path)
    c = app.ctrl
    ring = app.telemetry
    app.set_param("host_timeout_ms", 0)  # watchdog off: the silence count must stop by itself
    app.set_stream(app.board["loop_hz"])  # a record every step
    app.set_mode(mode)
    app.set_target(target)
    run_steps(app.step, 20)
    period = c.period_us
    c.t_us = MASK - 4 * period + 1  # wraps on the 4th step from here
    c.steps = MASK - 2
    ring.head = ring.tail = MASK - 5
    app.safety.silence = SILENCE_CAP - 3
    dst = array("i", [0] * 12)
    ts = array("i", [0] * 24)
    k = 0
    lock = micropython is not None and hasattr(micropython, "heap_lock")
    if lock:
        micropython.heap_lock()
    try:
        i = 0
        while i < 12:
            app.step(None)
            while ring.read_into(dst):  # drain as the link does, also across the wrap
                ts[k] = dst[0]
                k += 1
            i += 1
    finally:
        if lock:
            micropython.heap_unlock()
    st = app.status()
    assert st["faults"] == [], st
    t = list(ts[:k])
    assert k == 12, t
    assert max(t) > MASK - 4 * period and min(t) < 8 * period, t  # t_us crossed 2**30
    for a, b in zip(t, t[1:]):
        assert (b - a) & MASK == period, t  # no step lost or doubled across the wrap
    assert c.steps == 9, c.steps  # MASK - 2 + 12 steps, mod 2**30
    assert ring.head < 12 and ring.dropped == 0, (ring.head, ring.dropped)
    assert app.safety.silence == SILENCE_CAP, app.safety.silence
    # what both interpreters must agree on bit for bit, taken before the steps whose number
    # depends on the clock (a loaded host made the emulated M0 take 54 steps where CPython took 24)
    agreed = {"t_us": t, "steps": c.steps, "head": ring.head, "silence": app.safety.silence, "duty": c.duty}
    # the overrun count saturates: with a 1 us period nearly every step is an overrun (one whose
    # own clock did not move by a whole microsecond is not: the emulated chip's clock is coarse
    # and a loaded host makes it coarser), so step until it has saturated, then some more
    c.overruns = MASK - 2
    c.period_us = 1
    n = 0
    while c.overruns < MASK and n < 400:
        _locked(app.step, 5)
        n += 5
    assert c.overruns == MASK, c.overruns
    _locked(app.step, 10)
    assert c.overruns == MASK, c.overruns
    assert app.status()["faults"] == [], app.status()
    assert app.safety.silence == SILENCE_CAP, app.safety.silence
    agreed["overruns"] = c.overruns
    return agreed
