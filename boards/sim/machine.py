"""A module shaped like MicroPython's `machine`, backed by the simulated actuator.

`configure(board, seed)` builds the world from a board dict (boards/sim.json); `for_board(path)`
does it from a board file and returns the module, the firmware's `machine`. Pins are labels:
an ADC pin's label names the sensor channel meant for it ("pot1" carries the nut's pot), motor
pins the H-bridge inputs (board["motor_pins"]). Where the wires really go, and the motor voltage
the bridge makes of its inputs, is boards/sim/harness.py (the actuator's `wiring` can say that it
is wired wrongly, as a first bench often is; host calibrate bringup finds it).
Time: `run_ticks(n)` advances physics one timer period and then fires the timer callback, n times
(deterministic, for tests); `idle()` does the same for each tick due by the wall clock (the
real-time virtual board), catching up at most max_catchup_ticks at once and counting the rest
in `skipped_ticks`. Setters and ADC reads only store or read small ints, so a firmware step that
calls them can run under micropython.heap_lock(); the float physics runs between callbacks.
"""

import time

from boards.sim import bench_rig
from boards.sim.actuator import CHANNELS, Actuator
from boards.sim.harness import Harness

_world = None
_board = None
_harness = None
_timer = None
_pins = {}  # label -> Pin (the last one made for that label)
_pwms = {}  # label -> PWM
ticks = 0  # timer ticks fired (run_ticks and idle)
skipped_ticks = 0  # ticks idle() dropped after a stall instead of catching up
_next_due = 0
_max_catchup = 20
_persist = False  # keep_world(): the actuator outlives firmware restarts in this process

try:
    _ticks_us = time.ticks_us
    _ticks_diff = time.ticks_diff
    _ticks_add = time.ticks_add
    _sleep_us = time.sleep_us
except AttributeError:  # CPython

    def _sleep_us(us):
        time.sleep(us / 1000000)

    def _ticks_us():
        return int(time.perf_counter() * 1000000)

    def _ticks_diff(a, b):
        return a - b

    def _ticks_add(a, b):
        return a + b


def keep_world(flag=True):
    """After keep_world(), configure() for the same board keeps the existing actuator (position,
    time, faults, load) and only resets the peripherals: a firmware restart or soft reset resets
    the MCU, not the mechanics. For the long-running virtual board; tests get a fresh world."""
    global _persist
    _persist = bool(flag)


def configure(board, seed=None):
    """Create the simulated world for this board (a fresh actuator, no timer, motor off)."""
    global _world, _board, _harness, _timer, _pins, _pwms, ticks, skipped_ticks, _max_catchup
    params = dict(board["actuator"])
    params["adc_bits"] = board["adc_bits"]
    same = _world is not None and _board is not None and _board.get("name") == board.get("name")
    if _persist and same:
        _world.set_motor_voltage(0.0)  # the bridge is unpowered while the MCU restarts
    else:
        _world = Actuator(params, board.get("seed", 0) if seed is None else seed)
        ticks = 0
        skipped_ticks = 0
    _board = board
    # Pins here are labels, each the name of the sensor or bridge input it was meant for, so the
    # harness is built from those names: a board file corrected by bringup names other labels,
    # the wires stay where they are
    _harness = Harness(dict(board, adc_pins=dict((c, c) for c in CHANNELS)), params)
    _timer = None
    _pins = {}
    _pwms = {}
    _max_catchup = int(params.get("machine", {}).get("max_catchup_ticks", 20))
    return _world


def for_board(path):
    """Build the world for the board file at `path` and return this module: the `machine` a
    simulated board's firmware runs on (the virtual board installs it as `machine` before the
    firmware boots; tests hand it to App as machine=)."""
    import json

    import boards.sim.machine as this

    with open(path) as f:
        board = json.load(f)
    configure(board, board.get("seed"))
    return this


def world():
    """The Actuator behind this module (tests read and steer the physics through it)."""
    if _world is None:
        raise RuntimeError("boards.sim.machine.configure(board) was not called")
    return _world


def _label(pin):
    return pin.id if isinstance(pin, Pin) else pin


class Pin:
    IN = 0
    OUT = 1
    PULL_UP = 1
    PULL_DOWN = 2

    def __init__(self, id, mode=-1, pull=None, value=None):
        self.id = id
        self.mode = mode
        self._value = 0 if value is None else (1 if value else 0)
        _pins[id] = self

    def value(self, v=None):
        if v is None:
            return self._value
        self._value = 1 if v else 0

    def on(self):
        self._value = 1

    def off(self):
        self._value = 0

    def __call__(self, v=None):
        return self.value(v)


class ADC:
    def __init__(self, pin, *args, **kwargs):
        label = _label(pin)
        world()
        try:
            name, reversed_track = _harness.channel(label)
        except ValueError:
            raise ValueError("pin %r is not an ADC pin of board %s" % (label, _board["name"]))
        self.channel = name
        self._i = CHANNELS.index(name)
        self._w = _world
        # a track wired end for end reads the complement: 65535 - v, exactly ~v in 16 bits
        self._flip = 0xFFFF if reversed_track else 0

    def read_u16(self):
        return self._w.read_u16_index(self._i) ^ self._flip


class PWM:
    def __init__(self, pin, freq=1000, duty_u16=0, **kwargs):
        self.pin = _label(pin)
        self._freq = freq
        self._duty = 0
        self.duty_u16(duty_u16)
        _pwms[self.pin] = self

    def duty_u16(self, value=None):
        if value is None:
            return self._duty
        if value < 0 or value > 65535:
            raise ValueError("duty_u16 must be 0..65535")
        self._duty = value

    def freq(self, value=None):
        if value is None:
            return self._freq
        self._freq = value

    def init(self, freq=None, duty_u16=None, **kwargs):
        if freq is not None:
            self._freq = freq
        if duty_u16 is not None:
            self.duty_u16(duty_u16)

    def deinit(self):
        self._duty = 0


class Timer:
    ONE_SHOT = 0
    PERIODIC = 1

    def __init__(self, id=-1, **kwargs):
        self.id = id
        self.callback = None
        self.period_s = 0.0
        self.period_us = 0
        self.mode = Timer.PERIODIC
        if kwargs:
            self.init(**kwargs)

    def init(self, freq=None, period=None, mode=1, callback=None, hard=None, **kwargs):
        global _timer, _next_due
        if freq is None:
            freq = 1000.0 / period if period else _board.get("loop_hz", 1000)
        self.period_s = 1.0 / freq
        self.period_us = int(1000000 // freq)
        self.mode = mode
        self.callback = callback
        _timer = self
        _next_due = _ticks_add(_ticks_us(), self.period_us)

    def deinit(self):
        global _timer
        self.callback = None
        if _timer is self:
            _timer = None


def _level(label):
    """A bridge input's level, 0..1: a PWM pin's duty, else an output pin's value."""
    p = _pwms.get(label)
    if p is not None:
        return p._duty / 65535.0
    pin = _pins.get(label)
    return 1.0 if (pin is not None and pin._value) else 0.0


def motor_voltage():
    """Voltage across the motor from the present PWM duties and pin levels."""
    return _harness.motor_volts(_level)


def _tick():
    global ticks
    w = _world
    w.set_motor_voltage(motor_voltage())
    t = _timer
    w.advance(t.period_s if t is not None else 1.0 / _board.get("loop_hz", 1000))
    ticks += 1
    if t is not None and t.callback is not None:
        cb = t.callback
        if t.mode == Timer.ONE_SHOT:
            t.deinit()
        cb(t)


def run_ticks(n):
    """Advance physics by n timer periods, firing the timer callback after each."""
    world()
    i = 0
    while i < n:
        _tick()
        i += 1
    return n


def idle():
    """Run every tick that is due by the wall clock; return how many ran. When none is due,
    sleep until the next one is (at most one period) instead of returning at once: a real board's
    main loop spins between timer interrupts, but a virtual board that spun would hold a whole
    core of the host computer (the suite's and the user's), and its input waits at most one
    period for the next main-loop visit, as on a board busy in its step."""
    global _next_due, skipped_ticks
    bench_rig.poll(_world)  # what a person mounted on the rig (rig.json), outside the step
    t = _timer
    if t is None:
        return 0
    now = _ticks_us()
    late = _ticks_diff(now, _next_due)
    if late < 0:
        _sleep_us(min(-late, t.period_us))
        return 0
    n = late // t.period_us + 1
    if n > _max_catchup:
        skipped_ticks += n - _max_catchup
        n = _max_catchup
        _next_due = _ticks_add(now, t.period_us)
    else:
        _next_due = _ticks_add(_next_due, n * t.period_us)
    run_ticks(n)
    return n


def time_to_next_tick_us():
    """Microseconds until idle() has a tick to run (0 when one is due): lets a real-time loop
    sleep instead of spinning. None when no timer runs."""
    if _timer is None:
        return None
    late = _ticks_diff(_ticks_us(), _next_due)
    return 0 if late >= 0 else -late


def unique_id():
    return b"LSEA-SIM"


def reset_cause():
    return 0


def freq():
    return 125000000


def disable_irq():
    return 0


def enable_irq(state=0):
    pass
