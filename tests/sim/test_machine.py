"""The machine-shaped module of the simulated board: driver wirings, timer ticks, wall-clock
idle, allocation-free ADC/PWM/Pin calls, and the firmware's own motor driver on top of it."""

import json

import pytest
from tests.sim.scenarios import REPO, run_both, run_each
from testkit.interpreters import run_micropython

BOARD = json.loads((REPO / "boards" / "sim.json").read_text())


def test_two_pwm_and_pwm_dir_duties_map_to_motor_voltage():
    r = run_both("""
out = {}
machine.configure(BOARD)
a = machine.PWM(machine.Pin('in1', machine.Pin.OUT), freq=20000, duty_u16=0)
b = machine.PWM(machine.Pin('in2', machine.Pin.OUT), freq=20000, duty_u16=0)
two = []
for d1, d2 in ((30000, 0), (0, 65535), (65535, 65535), (0, 0), (1000, 21000)):
    a.duty_u16(d1)
    b.duty_u16(d2)
    machine.run_ticks(1)
    two.append((machine.motor_voltage(), machine.world().volts))
out['two_pwm'] = two
board = dict(BOARD)
board['driver'] = 'pwm_dir'
board['motor_pins'] = {'pwm': 'en', 'dir': 'ph'}
machine.configure(board)
p = machine.PWM(machine.Pin('en', machine.Pin.OUT), freq=20000, duty_u16=0)
ph = machine.Pin('ph', machine.Pin.OUT, value=0)
pd = []
for level, duty in ((1, 30000), (0, 30000), (1, 65535), (0, 0)):
    ph.value(level)
    p.duty_u16(duty)
    machine.run_ticks(1)
    pd.append((machine.motor_voltage(), machine.world().volts))
p.deinit()
pd.append((machine.motor_voltage(), 0.0))
out['pwm_dir'] = pd
emit(out)
""")
    s = BOARD["supply_volts"]
    want = [s * 30000 / 65535, -s, 0.0, 0.0, -s * 20000 / 65535]
    for (v, applied), w in zip(r["two_pwm"], want):
        assert v == pytest.approx(w, abs=1e-12) and applied == v
    want = [s * 30000 / 65535, -s * 30000 / 65535, s, 0.0, 0.0]
    for (v, applied), w in zip(r["pwm_dir"][:4], want):
        assert v == pytest.approx(w, abs=1e-12) and applied == v
    assert r["pwm_dir"][4][0] == 0.0  # deinit leaves the motor unpowered


def test_run_ticks_advances_one_period_then_fires_the_callback_each_time():
    r = run_both("""
machine.configure(BOARD)
seen = []
def cb(t):
    seen.append((machine.ticks, machine.world().time_s))
t = machine.Timer(-1)
t.init(freq=500, mode=machine.Timer.PERIODIC, callback=cb)
machine.run_ticks(7)
t.deinit()
machine.run_ticks(3)  # physics still runs at loop_hz, no callback once the timer is off
emit({'seen': seen, 'ticks': machine.ticks, 'time': machine.world().time_s})
""")
    assert [s[0] for s in r["seen"]] == list(range(1, 8))
    for k, (_, t) in enumerate(r["seen"], start=1):
        assert t == pytest.approx(k * 0.002, abs=1e-12)
    assert r["ticks"] == 10
    assert r["time"] == pytest.approx(0.002 * 7 + 3 / BOARD["loop_hz"], abs=1e-12)


def test_idle_runs_the_ticks_due_by_its_clock_and_caps_catch_up_after_a_stall():
    """idle() on a clock the scenario steps by hand (machine._ticks_us replaced): exact tick
    counts whatever the machine's load. On MicroPython the clock starts just short of the
    ticks_us wrap, so the catch-up arithmetic is checked across it."""
    r = run_both("""
clock = [machine._ticks_add(0, -5000)]  # CPython: -5000 us; MicroPython: 5 ms before the wrap
machine._ticks_us = lambda: clock[0]
def advance(us):
    clock[0] = machine._ticks_add(clock[0], us)
slept = []
machine._sleep_us = slept.append  # a few entries: only calls with no tick due sleep
machine.configure(BOARD)
n = [0]
def cb(t):
    n[0] += 1
t = machine.Timer(-1)
t.init(freq=1000, mode=machine.Timer.PERIODIC, callback=cb)
out = {'cap': PARAMS['machine']['max_catchup_ticks']}
out['early'] = (machine.idle(), machine.time_to_next_tick_us())
advance(999)
out['almost'] = (machine.idle(), machine.time_to_next_tick_us())
advance(1)
out['due'] = (machine.idle(), machine.time_to_next_tick_us())
advance(2500)  # 2.5 periods late: the two due ticks run, the next is half a period away
out['late'] = (machine.idle(), machine.time_to_next_tick_us())
advance(200000)  # a 200 ms stall: 200 ticks due at once
out['stall'] = (machine.idle(), machine.skipped_ticks, machine.time_to_next_tick_us())
ran = 0
lo = hi = machine.time_to_next_tick_us()
for i in range(300):  # keeping up afterwards: one period at a time, bounded memory
    advance(1000)
    ran += machine.idle()
    w = machine.time_to_next_tick_us()
    lo = min(lo, w)
    hi = max(hi, w)
out['after'] = (ran, lo, hi, machine.skipped_ticks)
out['count'] = (n[0], machine.ticks)
out['slept'] = slept
emit(out)
""")
    cap = r["cap"]
    assert r["early"] == [0, 1000]
    assert r["almost"] == [0, 1]
    assert r["due"] == [1, 1000]
    assert r["late"] == [2, 500]
    # 199.5 ms past the due tick: 200 ticks due, cap run, the rest dropped, the next a period on
    assert r["stall"] == [cap, 200 - cap, 1000]
    assert r["after"] == [300, 1000, 1000, 200 - cap]
    assert r["count"] == [1 + 2 + cap + 300] * 2
    # with no tick due, idle() sleeps until the next one (early: a period; almost: 1 us) rather
    # than returning at once into a spinning main loop; with a tick due it never sleeps
    assert r["slept"] == [1000, 1]


def test_idle_follows_the_real_wall_clock():
    """The same on the real clock, asserting only what no load can change: a sleep of 200 ms
    makes at least 200 ticks due (so the cap runs and at least 200 - cap are dropped), idle()
    never runs a tick before it is due, and it never waits more than one period. A fixed
    number of idle() calls (not a wall-clock span; each sleeps at most a period), and no list,
    so a fast machine does no more work and holds no more memory than a slow one."""
    results = run_each("""
import time
machine.configure(BOARD)
n = [0]
def cb(t):
    n[0] += 1
t = machine.Timer(-1)
t.init(freq=1000, mode=machine.Timer.PERIODIC, callback=cb)
t0 = machine._ticks_us()
time.sleep(0.2)
stalled = machine.idle()
skipped = machine.skipped_ticks
ran = 0
lo = hi = machine.time_to_next_tick_us()
for i in range(1000):
    ran += machine.idle()
    w = machine.time_to_next_tick_us()
    lo = min(lo, w)
    hi = max(hi, w)
elapsed_us = machine._ticks_diff(machine._ticks_us(), t0)
emit({'stalled': stalled, 'skipped': skipped, 'ran': ran, 'lo': lo, 'hi': hi, 'elapsed_us': elapsed_us,
      'cap': PARAMS['machine']['max_catchup_ticks'], 'calls': n[0], 'ticks': machine.ticks,
      'skipped_end': machine.skipped_ticks})
""")
    for r in results:
        assert r["stalled"] == r["cap"]
        assert r["skipped"] >= 200 - r["cap"]
        assert r["calls"] == r["ticks"] == r["stalled"] + r["ran"]
        # every tick run or dropped was due: never ahead of the clock
        assert r["ticks"] + r["skipped_end"] <= r["elapsed_us"] // 1000 + 1
        assert 0 <= r["lo"] and r["hi"] <= 1000


def test_adc_pwm_and_pin_calls_allocate_nothing_under_heap_lock():
    out = run_micropython("""
import json, micropython
import boards.sim.machine as machine
machine.configure(json.load(open('boards/sim.json')))
adcs = [machine.ADC(machine.Pin(n)) for n in ('pot1', 'pot2', 'reference', 'gauge')]
a1, a2, ar, ag = adcs
pwm = machine.PWM(machine.Pin('in1', machine.Pin.OUT), freq=20000, duty_u16=0)
pin = machine.Pin('in2', machine.Pin.OUT, value=0)
def step(t):
    s = a1.read_u16() + a2.read_u16() + ar.read_u16() + ag.read_u16()
    pwm.duty_u16(s >> 2)
    pwm.duty_u16()
    pin.value(1)
    pin.value()
machine.Timer(-1).init(freq=1000, callback=step)
machine.world().inject_fault('pot2', 'wiper_lift')
micropython.heap_lock()
try:
    step(None)
    step(None)
    print('clean')
except MemoryError:
    print('allocated')
micropython.heap_unlock()
machine.run_ticks(5)  # the float physics runs between callbacks, outside the lock
print(machine.ticks)
""").stdout.split()
    assert out == ["clean", "5"]


def test_adc_on_a_pin_that_is_not_an_adc_pin_is_refused():
    from boards.sim import machine

    machine.configure(BOARD)
    with pytest.raises(ValueError):
        machine.ADC(machine.Pin("in1"))
    with pytest.raises(ValueError):
        machine.PWM("in1", freq=20000, duty_u16=70000)


@pytest.mark.parametrize("driver", ["two_pwm", "pwm_dir"])
def test_firmware_motor_driver_moves_the_nut_toward_larger_d1_for_positive_duty(driver):
    """The contract with firmware/motor.py: positive duty = nut toward larger D1."""
    r = run_both("""
from firmware.motor import Motor
from firmware.pi_control import DUTY_MAX
board = dict(BOARD)
board['driver'] = %r
if board['driver'] == 'pwm_dir':
    board['motor_pins'] = {'pwm': 'en', 'dir': 'ph'}
out = []
for sign in (1, -1):
    machine.configure(board)
    m = Motor(machine, board)
    m.set(sign * DUTY_MAX // 2)
    x0 = machine.world().nut_mm
    machine.run_ticks(200)
    moved = machine.world().nut_mm - x0
    m.off()
    out.append((moved, machine.motor_voltage()))
emit({'out': out})
""" % driver)
    (up, v_off1), (down, v_off2) = r["out"]
    assert up > 1.0 and down < -1.0
    assert v_off1 == 0.0 and v_off2 == 0.0


def test_keep_world_survives_a_firmware_restart_but_peripherals_reset():
    r = run_both("""
machine.configure(BOARD)
machine.configure(BOARD)
fresh = machine.world().block_mm
p = machine.PWM(machine.Pin('in1'), freq=20000, duty_u16=40000)
machine.run_ticks(300)
moved = machine.world().block_mm
machine.keep_world()
machine.configure(BOARD)  # what booting again does (for_board at the virtual board's boot)
kept = (machine.world().block_mm, machine.ticks, machine.motor_voltage())
machine.keep_world(False)
machine.configure(BOARD)
reset = (machine.world().block_mm, machine.ticks)
emit({'fresh': fresh, 'moved': moved, 'kept': kept, 'reset': reset})
""")
    start = BOARD["actuator"]["start"]["block_mm"]
    assert r["fresh"] == start and r["moved"] > start + 5
    assert r["kept"] == [r["moved"], 300, 0.0]
    assert r["reset"] == [start, 0]
