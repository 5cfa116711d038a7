"""Benchmark: microseconds and heap bytes per control step on the real MicroPython unix port.

Times the firmware's fixed-point step as shipped (firmware/controller.py) in every mode, with
BCM-3 pots (the paper's calibration) and with pwl-table pots, against an equivalent float step
in the same run (same ADC replay, same conversions in float: rational Bernstein or table
interpolation, Horner Df and force, the friction play operator and its band-edge choice, float PI,
stroke and slew limits). ADC codes are recorded
from the simulated actuator; calibrations are fitted and exported from it.

    .venv/bin/python bench/bench_control_step.py [--steps 5000]

The top of this file is portable (MicroPython imports it for FloatStep); the driver below
`if __name__ == "__main__"` runs on CPython and starts MicroPython.
"""

import time

try:
    import gc
except ImportError:  # pragma: no cover
    gc = None


class FloatStep:
    """The same step in floats: what the firmware would do with float math (it allocates)."""

    def __init__(self, app, fcal):
        self.app = app
        self.s = app.sampler
        self.c = fcal
        self.integ = 0.0
        self.duty = 0.0
        self.kp = 768 / 256.0
        self.ki = 16 / 65536.0
        self.kpf = 2560 / 256.0
        self.kif = 8192 / 65536.0
        self.mode = 0
        self.target = 0.0
        self.ff = None  # low-passed spring force, N
        self.out = 0.0  # the play operator's output, N
        self.fdir = 0

    def pot(self, sec, code):
        if sec[0] == "bcm":
            lx, rx, w, p = sec[1], sec[2], sec[3], sec[4]
            t = (code - lx) / rx
            t = 0.0 if t < 0.0 else (1.0 if t > 1.0 else t)
            u = 1.0 - t
            b0 = u * u * u * w[0]
            b1 = 3.0 * t * u * u * w[1]
            b2 = 3.0 * t * t * u * w[2]
            b3 = t * t * t * w[3]
            return (b0 * p[0] + b1 * p[1] + b2 * p[2] + b3 * p[3]) / (b0 + b1 + b2 + b3)
        xs, ys = sec[1], sec[2]
        if code <= xs[0]:
            return ys[0]
        n = len(xs)
        if code >= xs[n - 1]:
            return ys[n - 1]
        lo, hi = 0, n - 1
        while hi - lo > 1:
            mid = (lo + hi) >> 1
            if xs[mid] <= code:
                lo = mid
            else:
                hi = mid
        return ys[lo] + (ys[hi] - ys[lo]) * (code - xs[lo]) / (xs[hi] - xs[lo])

    def horner(self, a, x):
        r = 0.0
        for c in a:
            r = r * x + c
        return r

    def step(self, _timer=None):
        s = self.s
        s.sample()
        c = self.c
        d1 = self.pot(c["pot1"], s.raw1)
        d1 = d1 - self.horner(c["df"], d1)
        d2 = self.pot(c["pot2"], s.raw2)
        defl = d1 - d2
        force = self.horner(c["force"], defl)
        h = c["friction"]
        if h:
            self.ff = force if self.ff is None else self.ff + (force - self.ff) / 64.0
            if self.ff > self.out + h:
                self.out = self.ff - h
            elif self.ff < self.out - h:
                self.out = self.ff + h
            force = self.out
        if self.mode == 1:
            cmd = self.target
        elif self.mode == 2 or self.mode == 3:
            if self.mode == 2:
                e = self.target - d2 * 1000.0
                kp, ki = self.kp, self.ki
            else:
                ef = self.target / 1000.0 - force
                if ef < -h / 8.0:
                    self.fdir = 1
                elif ef > h / 8.0:
                    self.fdir = -1
                e = self.horner(c["force_inverse"], self.target / 1000.0 - h * self.fdir) * 1000.0 - defl * 1000.0
                kp, ki = self.kpf, self.kif
            u = kp * e + self.integ
            if -8000.0 < u < 8000.0:
                self.integ = max(-6000.0, min(6000.0, self.integ + ki * e))
            cmd = max(-8000.0, min(8000.0, kp * e + self.integ))
        else:
            cmd = 0.0
        pos_hi = d1 if d1 > d2 else d2
        pos_lo = d1 if d1 < d2 else d2
        room = (59.5 - pos_hi) if cmd > 0 else (pos_lo - 0.5)
        cap = 0.0 if room <= 0.0 else (10000.0 * room / 5.0 if room < 5.0 else 10000.0)
        if cmd > cap:
            cmd = cap
        elif cmd < -cap:
            cmd = -cap
        step = 500.0
        duty = self.duty + max(-step, min(step, cmd - self.duty))
        self.duty = duty
        self.app.motor.set(int(duty))
        return force


def _loop(f, n):
    i = 0
    while i < n:
        f(None)
        i += 1


def measure(f, n):
    """(us per call, heap bytes allocated per call). Time is over n calls with the collector
    on (its cost is part of what allocation costs); bytes over 500 calls with it off."""
    _loop(f, 50)
    gc.collect()
    gc.disable()
    a = gc.mem_alloc()
    _loop(f, 500)
    b = gc.mem_alloc()
    gc.enable()
    gc.collect()
    t0 = time.ticks_us()
    _loop(f, n)
    dt = time.ticks_diff(time.ticks_us(), t0)
    return dt / n, (b - a) / 500


def run_all(path, n):
    from testkit.replay import load, replay_app

    data = load(path)
    rows = []
    for kind in ("bcm3", "pwl"):
        for mode, target, ftarget in (("idle", 0, 0), ("open_loop", 2500, 2500.0),
                                      ("position", 31000, 31000.0), ("force", 2000, 2000.0)):
            app, _ = replay_app(data, calibration=kind)
            app.set_param("host_timeout_ms", 600000)
            app.set_stream(100)
            app.set_mode(mode)
            app.set_target(target)
            us, alloc = measure(app.step, n)
            fs = FloatStep(app, data["float"][kind])
            fs.mode = ("idle", "open_loop", "position", "force").index(mode)
            fs.target = ftarget
            fus, falloc = measure(fs.step, n)
            rows.append((kind, mode, us, alloc, fus, falloc))
    return rows


def _prepare(path):
    """CPython: record ADC codes from the sim and write bcm3 and pwl calibration files beside them
    (the model calibration of testkit.model; the bcm3 pots fitted to one noisy read per place)."""
    import json
    from pathlib import Path

    from boards.sim.actuator import Actuator
    from host.calibration.file import write_calibration
    from host.calibration.fixed_export import export_bcm3
    from testkit import model

    board = model.sim_board()
    pwl = model.model_document(board)
    world = Actuator(dict(board["actuator"], adc_bits=board["adc_bits"]), 3)
    bcm = dict(pwl)
    fl = {"bcm3": {}, "pwl": {}}
    for name, fit in model.bcm3_pot_fits(board, noisy=True, seed=3).items():
        c = fit.coefficients
        bcm[name] = {"kind": "bcm3", "fixed": list(export_bcm3(c, board["adc_bits"], max_error_um=1e9))}
        fl["bcm3"][name] = ["bcm", c["lx"], c["rx"], list(c["weights"]), list(c["handles"])]
        k = pwl[name]["fixed"]
        n, s = k[0], k[1]
        fl["pwl"][name] = ["pwl", [v / 2**s for v in k[2:2 + n]], [v / 1000.0 for v in k[2 + n:]]]
    # float polynomials (mm domain) fitted the same way the model calibration does
    for kind in fl:
        fl[kind].update(_float_polys(board, world))
    calibrations = {}
    for kind, doc in (("bcm3", bcm), ("pwl", pwl)):
        calibrations[kind] = str(Path(path).with_name("%s.json" % kind))
        write_calibration(calibrations[kind], doc)
    data = {"codes": model.record_codes(board, steps=400, duty=3000), "calibrations": calibrations, "float": fl}
    with open(path, "w") as f:
        json.dump(data, f)


def _float_polys(board, world):
    import numpy as np

    xs = np.linspace(0.0, 60.0, 61)
    d1 = np.array([x + world.pots[0].mount_error_mm(x) for x in xs])
    d2 = np.array([x + world.pots[1].mount_error_mm(x) for x in xs])
    cav = float(board["actuator"]["springs"]["cavity_mm"])
    d = np.linspace(-cav, cav, 401)
    f = np.array([world.spring_force(v) for v in d])
    return {"df": list(np.polyfit(d1, d1 - d2, 8)), "force": list(np.polyfit(d, f, 3)),
            "force_inverse": list(np.polyfit(f, d, 3)), "friction": float(board["actuator"]["block"]["coulomb_n"])}


def main():
    import argparse
    import json
    import tempfile
    from pathlib import Path

    from testkit.interpreters import run_micropython

    here = Path(__file__).resolve().parent

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--steps", type=int, default=5000, help="steps timed per mode (default 5000)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        path = str(Path(tmp) / "bench.json")
        print("recording ADC codes and calibrations from the simulated actuator ...", flush=True)
        _prepare(path)
        print("timing %d steps per mode on MicroPython ..." % args.steps, flush=True)
        proc = run_micropython(
            "import json, bench_control_step as b\nprint(json.dumps(b.run_all(%r, %d)))" % (path, args.steps),
            extra_paths=[here], timeout=600,
        )
    rows = json.loads(proc.stdout.strip().splitlines()[-1])
    print("%-5s %-10s %14s %14s %14s %14s %8s" % ("pots", "mode", "fixed us/step", "fixed B/step",
                                                 "float us/step", "float B/step", "speedup"))
    for kind, mode, us, alloc, fus, falloc in rows:
        print("%-5s %-10s %14.1f %14.1f %14.1f %14.1f %7.2fx" % (kind, mode, us, alloc, fus, falloc, fus / us))


if __name__ == "__main__":
    main()
