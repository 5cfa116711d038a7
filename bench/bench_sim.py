"""Speed of the simulated actuator: microseconds per 1 ms physics tick, MicroPython and CPython.

The virtual board runs the world in real time at loop_hz = 1000, so one tick (physics plus the
firmware's ADC reads) must take well under 1 ms on the host. Run from the repository root:

    .venv/bin/python bench/bench_sim.py          # CPython figures, then the real micropython's
    MICROPYPATH=.frozen:. .venv/bin/micropython bench/bench_sim.py   # MicroPython only
"""

import json
import sys
import time

try:
    _now = time.ticks_us
    _diff = time.ticks_diff
except AttributeError:  # CPython

    def _now():
        return int(time.perf_counter() * 1000000)

    def _diff(a, b):
        return a - b


TICKS = 2000
REPEATS = 5


def bench(board, load, reads_per_channel, duty_writes):
    import boards.sim.machine as machine

    machine.configure(board)
    w = machine.world()
    if load == "gauge":
        w.place(50.0)
        w.set_load("gauge")
    adcs = [machine.ADC(machine.Pin(board["adc_pins"][n])) for n in ("pot1", "pot2", "reference")]
    a1, a2, ar = adcs
    pins = board["motor_pins"]
    p1 = machine.PWM(machine.Pin(pins["in1"], machine.Pin.OUT), freq=20000, duty_u16=0)
    p2 = machine.PWM(machine.Pin(pins["in2"], machine.Pin.OUT), freq=20000, duty_u16=0)
    reads = reads_per_channel
    sign = -1 if load == "gauge" else 1

    def step(t):
        i = 0
        while i < reads:
            a1.read_u16()
            a2.read_u16()
            ar.read_u16()
            i += 1
        if duty_writes:
            if sign > 0:
                p2.duty_u16(0)
                p1.duty_u16(20000)
            else:
                p1.duty_u16(0)
                p2.duty_u16(20000)

    machine.Timer(-1).init(freq=board["loop_hz"], mode=machine.Timer.PERIODIC, callback=step)
    best = None
    for _ in range(REPEATS):  # best of a few: other jobs on the host only ever add time
        t0 = _now()
        machine.run_ticks(TICKS)
        us = _diff(_now(), t0) / TICKS
        best = us if best is None or us < best else best
    return best, w._n_sub


def bench_configure(board):
    import boards.sim.machine as machine

    t0 = _now()
    machine.configure(board)
    return _diff(_now(), t0) / 1000.0


def main():
    with open("boards/sim.json") as f:
        board = json.load(f)
    impl = sys.implementation.name
    print("%s %s: configure() (noise table) %.1f ms" % (
        impl, ".".join(str(v) for v in sys.implementation.version[:3]), bench_configure(board)))
    over = board.get("oversample", 4)
    for load, reads, writes, label in (
        ("none", 0, False, "physics only"),
        ("none", 1, True, "physics + 3 ADC reads + 2 duty writes"),
        ("none", over, True, "physics + 3 x oversample ADC reads + 2 duty writes"),
        ("gauge", over, True, "same, force-gauge load (stiffer, more sub-steps)"),
    ):
        us, nsub = bench(board, load, reads, writes)
        print("%s: %7.1f us per 1 ms tick, best of %d x %d  (%d sub-steps, %s)"
              % (impl, us, REPEATS, TICKS, nsub, label))


if __name__ == "__main__":
    main()
    if sys.implementation.name == "cpython":
        import os
        import subprocess

        from testkit.interpreters import REPO, micropython_env, micropython_executable

        here = os.path.dirname(os.path.abspath(__file__))

        cmd = [micropython_executable(), "-X", "heapsize=8M", os.path.join(here, "bench_sim.py")]
        subprocess.run(cmd, cwd=str(REPO), env=micropython_env(), check=True)
