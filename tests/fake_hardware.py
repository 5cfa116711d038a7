"""Machine-shaped test hardware that replays ADC codes recorded from the simulated actuator.

For the heap_lock proof the step must run against an ADC whose read_u16() allocates nothing:
ReplayMachine's ADC returns codes from a preallocated array('H'), recorded beforehand from the
physical model (boards/sim) by the test, never made-up numbers. PWM and Pin remember what they
were told so tests can check the bridge; Timer is fired by the test. Portable: runs under
MicroPython and CPython.
"""

from array import array


class Pin:
    OUT = 1
    IN = 0

    def __init__(self, id, mode=-1, value=None):
        self.id = id
        self._v = 0 if value is None else value

    def value(self, v=None):
        if v is None:
            return self._v
        self._v = v


class PWM:
    def __init__(self, pin, freq=1000, duty_u16=0):
        self.pin = pin
        self._freq = freq
        self._duty = duty_u16
        self.deinited = False

    def duty_u16(self, v=None):
        if v is None:
            return self._duty
        self._duty = v

    def freq(self, f=None):
        if f is None:
            return self._freq
        self._freq = f

    def deinit(self):
        self._duty = 0
        self.deinited = True


class ReplayADC:
    def __init__(self, codes):
        self.codes = codes
        self.n = len(codes)
        self.i = 0

    def read_u16(self):
        i = self.i
        v = self.codes[i]
        i += 1
        if i >= self.n:
            i = 0
        self.i = i
        return v


class Timer:
    PERIODIC = 1
    ONE_SHOT = 0

    def __init__(self, id=-1):
        self.id = id
        self.callback = None
        self.freq = 0

    def init(self, freq=1000, mode=1, callback=None, hard=False):
        self.freq = freq
        self.callback = callback

    def deinit(self):
        self.callback = None

    def fire(self, n=1):
        cb = self.callback
        i = 0
        while i < n:
            cb(self)
            i += 1


class ReplayMachine:
    """`codes` maps an ADC pin id to a sequence of read_u16 values (replayed cyclically)."""

    Pin = Pin
    PWM = PWM
    Timer = Timer

    def __init__(self, codes):
        self.codes = {}
        for pin, seq in codes.items():
            self.codes[pin] = array("H", seq)
        self.adcs = {}

    def ADC(self, pin):
        adc = ReplayADC(self.codes[pin.id])
        self.adcs[pin.id] = adc
        return adc

    def rail(self, pin_id, start, value):
        """A wiper lift from replay position `start` on: every later read is the rail `value`."""
        codes = self.codes[pin_id]
        i = start
        while i < len(codes):
            codes[i] = value
            i += 1


# --- CPython side: calibrations and recordings made from the physical model (boards/sim) ------


def sim_board():
    import json

    with open("boards/sim.json") as f:
        return json.load(f)


def model_calibration(board=None, n_points=61, feed_forward=False):
    """A calibration of the simulated actuator, made the way the paper makes it, as plain data.

    Calibration 1: each pot against its own wiper travel (the reference rides with the pot),
    sampled noise-free over the stroke -> a pwl table (B's exporter). Calibration 2: Df = D1 - D2
    at zero load over the stroke, fitted by an 8th-order polynomial in D1 (Df is a quartic in the
    true position, not in D1, which pot 1's own mounting error distorts: order 4 leaves ~0.36 mm,
    order 8 ~26 um). Force: F0(d) and d(F0) fitted (cubic) to the model's spring curve over the
    cavity, and the block's Coulomb friction (with `feed_forward`, also the duty that holds the
    spring at that force, from the motor's stall force). Returns a JSON-able dict.
    """
    import numpy as np

    from boards.sim.actuator import Actuator
    from host.fixed_export import export_poly, export_pwl

    board = board or sim_board()
    params = dict(board["actuator"], adc_bits=board["adc_bits"])
    world = Actuator(params, 1)
    bits = board["adc_bits"]
    xs = np.linspace(0.0, 60.0, n_points)
    codes = {"pot1": [], "pot2": []}
    travel = {"pot1": [], "pot2": []}
    for x in xs:
        world.place(x)
        for i, name in enumerate(("pot1", "pot2")):
            codes[name].append(world.true_code(name))
            travel[name].append(x + world.pots[i].mount_error_mm(x))
    cal = {}
    for name in ("pot1", "pot2"):
        c = np.asarray(codes[name], dtype=float)
        t = np.asarray(travel[name], dtype=float)
        keep = np.concatenate([[True], np.diff(c) > 0])  # the table needs increasing codes
        cal[name] = ["pwl", list(export_pwl(c[keep], t[keep], bits, max_error_um=1e9))]
    d1 = np.asarray(travel["pot1"])
    df = d1 - np.asarray(travel["pot2"])
    cal["df"] = list(export_poly(np.polyfit(d1, df, 8), float(d1.min()), float(d1.max()), 1000, 1000, max_error=5))
    cav = float(board["actuator"]["springs"]["cavity_mm"])
    d = np.linspace(-cav, cav, 401)
    f = np.array([world.spring_force(v) for v in d])
    cal["force"] = list(export_poly(np.polyfit(d, f, 3), -cav, cav, 1000, 1000))
    cal["force_inverse"] = list(export_poly(np.polyfit(f, d, 3), float(f.min()), float(f.max()), 1000, 1000))
    h = float(board["actuator"]["block"]["coulomb_n"])
    cal["friction"] = [int(round(h * 1000))]  # the block's Coulomb, mN
    if feed_forward:  # and the duty at which the stalled motor holds the spring at that force
        stall_n = world.eta * world.kt * world.G * float(board["supply_volts"]) / world.R  # at full duty
        cal["friction"].append(int(round(h / (stall_n / 10000.0))))
    return cal


def bcm3_pot_fits(board, noisy=False, seed=1):
    """{pot: FitResult}: each pot's code against its own wiper travel over the stroke (601
    places), fitted by the paper's rational cubic Bezier (host.models). `noisy` takes one noisy
    ADC read per place (seeded) instead of the noise-free code."""
    import numpy as np

    from boards.sim.actuator import Actuator
    from host.models import fit_model

    world = Actuator(dict(board["actuator"], adc_bits=board["adc_bits"]), seed)
    xs = np.linspace(0.0, 60.0, 601)
    fits = {}
    for i, name in enumerate(("pot1", "pot2")):
        codes, travel = [], []
        for x in xs:
            world.place(x)
            codes.append(world.adc_code(name) if noisy else world.true_code(name))
            travel.append(x + world.pots[i].mount_error_mm(x))
        order = np.argsort(codes, kind="stable")
        fits[name] = fit_model("bcm", np.asarray(codes, float)[order], np.asarray(travel)[order], 3)
    return fits


def record_codes(board, steps, duty=3000, seed=7):
    """ADC read_u16 values of every ADC pin, recorded from the simulated actuator while the
    motor runs at `duty` (of 10000) for `steps` control periods from mid-stroke, for replay."""
    from boards.sim.actuator import Actuator

    params = dict(board["actuator"], adc_bits=board["adc_bits"])
    world = Actuator(params, seed)
    world.set_motor_voltage(board["supply_volts"] * duty / 10000.0)
    dt = 1.0 / board["loop_hz"]
    n = board["oversample"]
    out = {}
    for name in board["adc_pins"]:
        out[name] = []
    for _ in range(steps):
        world.advance(dt)
        for name in out:
            for _ in range(n):
                out[name].append(world.adc_u16(name))
    return out
