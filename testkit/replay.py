"""Machine-shaped test hardware that replays ADC codes recorded from the simulated actuator, and
the firmware's App booted on it (runs under MicroPython and CPython).

For the heap_lock proof the step must run against an ADC whose read_u16() allocates nothing:
ReplayMachine's ADC returns codes from a preallocated array('H'), recorded beforehand from the
physical model (boards/sim, testkit/model.py), never made-up numbers. PWM and Pin remember what
they were told so tests can check the bridge; Timer is fired by the test.

A replay data file (testkit.model.write_replay_data) holds the recorded codes per ADC channel and
the paths of calibration files written by the real calibration-file code; `replay_app` boots an
App on the codes with one of them, loaded by the firmware's own loader, as a board loads it.
"""

import json
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


def load(path):
    """A replay data file: {"codes": {channel: [read_u16 ...]}, "calibrations": {name: path}}."""
    with open(path) as f:
        return json.load(f)


def replay_app(data, calibration="model", board_path="boards/sim.json", exit_path=None):
    """(App, ReplayMachine): the App of board file `board_path` on a machine replaying
    data["codes"] on the board's ADC pins, with the calibration file data["calibrations"][name]
    (None: none) loaded by firmware.calibration, as at boot; its exit cause kept in the record
    at `exit_path` (hal.record: the file), if given."""
    from firmware.app import App
    from firmware.hal import record

    with open(board_path) as f:
        board = json.load(f)
    codes = {}
    for name, pin in board["adc_pins"].items():
        if name in data["codes"]:
            codes[pin] = data["codes"][name]
    machine = ReplayMachine(codes)
    app = App(board_path, None, machine=machine, exit_record=record(exit_path))
    if calibration is not None:
        app.set_calibration(load_calibration(data, calibration))
    return app, machine


def load_calibration(data, name="model"):
    """The firmware's Calibration of data["calibrations"][name]."""
    from firmware.calibration import load_calibration as load_file

    return load_file(data["calibrations"][name])


def pwm_duties(app):
    """The duty_u16 of each of the bridge's PWM outputs."""
    m = app.motor
    return [p.duty_u16() for p in (m.pwm_a, m.pwm_b) if p is not None]


def run_steps(step, n):
    """Call the control step `n` times, as the timer would (no allocation in the loop)."""
    i = 0
    while i < n:
        step(None)
        i += 1
