"""Cases of the firmware's App, its boot and its calibration, written once and run under both
CPython and MicroPython (testkit.interpreters: `both("tests.firmware.app_cases", "case_x(...)")`,
from tests/firmware/test_app.py): every module imports, the step allocates nothing under
heap_lock, the telemetry ring, the board files, and what the App does with the calibration it
finds (none, a broken file, another board's or ADC width's, end stops, a Df table, the load-force
play). The safety rules' cases are in safety_cases.py, the drive path's in drive_cases.py, the
parameters' in param_cases.py.

Each case takes plain data (a replay data file written by the CPython test: ADC codes recorded
from the simulated actuator and calibration files made from it, testkit.model) and raises
AssertionError on failure; it returns a small dict of figures that the CPython test also checks.
"""

import gc
from array import array

from testkit.replay import ReplayMachine, load, load_calibration, pwm_duties, replay_app, run_steps

try:
    import micropython
except ImportError:
    micropython = None

# Every firmware module (tests/firmware/test_app.py checks this against firmware/*.py).
MODULES = (
    "portable", "hal", "board_config", "sampler", "bcm_fixed", "pwl_fixed", "poly_fixed",
    "calibration", "measurement", "pi_control", "motor", "safety", "telemetry", "controller",
    "protocol", "link", "records", "saved_params", "param_table", "app", "board_main",
)
# ... but these, which import what only one runtime has (run on the emulated CircuitPython Pico
# by tests/link/test_emulated_circuitpython.py)
RUNTIME_ONLY = {"circuitpython_hw": "analogio, pwmio and digitalio: CircuitPython only"}


def case_imports():
    import firmware

    names = []
    for name in MODULES:
        __import__("firmware." + name)
        assert getattr(firmware, name) is not None
        names.append(name)
    return {"modules": names}


def case_heap_lock(path, mode, target, n=10000):
    """n control steps in `mode` with the heap locked: no MemoryError, no allocation."""
    data = load(path)
    app, _ = replay_app(data, calibration="model" if mode in ("position", "force") else None)
    app.set_param("host_timeout_ms", 600000)  # the watchdog runs, but must not stop this run
    app.set_stream(100)
    app.set_mode(mode)
    app.set_target(target)
    run_steps(app.step, 50)  # first calls settle attribute caches outside the lock
    gc.collect()
    before = gc.mem_alloc() if hasattr(gc, "mem_alloc") else 0
    locked = micropython is not None and hasattr(micropython, "heap_lock")
    if locked:
        micropython.heap_lock()
    try:
        run_steps(app.step, n)
    finally:
        if locked:
            micropython.heap_unlock()
    after = gc.mem_alloc() if hasattr(gc, "mem_alloc") else 0
    st = app.status()
    assert st["faults"] == [], st
    assert st["mode"] == mode, st
    from firmware.protocol import STATUS_KEYS

    assert sorted(st) == sorted(STATUS_KEYS), sorted(st)  # the interface table names every key
    assert app.ctrl.steps == n + 50
    if mode != "idle":
        assert app.ctrl.duty != 0, "the loop never drove the motor"
    assert app.telemetry.available() > 0
    cal = app.calibration
    pots = [cal.pot1[0], cal.pot2[0]] if cal is not None else None
    return {"locked": locked, "before": before, "after": after, "duty": app.ctrl.duty, "pots": pots}


def case_refused_without_calibration(path):
    data = load(path)
    app, _ = replay_app(data, calibration=None)
    for mode in ("position", "force"):
        try:
            app.set_mode(mode)
            raise AssertionError("closed loop accepted without calibration")
        except ValueError as exc:
            assert "calibration" in str(exc), str(exc)
    st = app.status()
    assert st["calibration_crc"] is None and st["calibration_error"], st
    app.set_mode("open_loop")  # raw readings and open loop still work
    app.set_target(2000)
    run_steps(app.step, 100)
    assert app.ctrl.duty == 2000 and app.sampler.raw1 > 0
    # a calibration without the force steps: position works, force is refused with the reason
    app.set_calibration(load_calibration(data, "pots_only"))
    app.set_mode("position")
    try:
        app.set_mode("force")
        raise AssertionError("force mode accepted without a force calibration")
    except ValueError as exc:
        assert "Df" in str(exc) or "force" in str(exc), str(exc)
    return {"error": st["calibration_error"]}


def case_load_force_play(path):
    """The load-force estimate with a calibrated block friction h is a play operator of width h
    on the (low-passed) spring force: it moves only when the spring force leaves the band, and
    `dir` says which edge moved last; deformation_targets put the spring at either edge."""
    from firmware.measurement import Measurement

    data = load(path)
    cal = load_calibration(data)
    h = cal.friction[0]
    m = Measurement(cal)
    seen = []
    for spring, expect in ((0, 0), (5000, 5000 - h), (4900, 5000 - h), (4000, 4000 + h), (4500, 4000 + h),
                           (-3000, -3000 + h), (-2800, -3000 + h), (-2000, -2000 - h)):
        i = 0
        while i < 800:  # the 64-step low-pass settles to within 1 mN of a 5 N step in ~550 steps
            out = m._load_force(spring)
            i += 1
        assert abs(out - expect) <= 2, (spring, out, expect)
        seen.append([out, m.dir])
    assert [d for _, d in seen] == [0, -1, -1, 1, 1, 1, 1, -1], seen
    targets = array("i", [0, 0, 0])
    m.deformation_targets(-5000, targets)
    assert targets[2] < targets[1] < targets[0], list(targets)  # s = +1 works from the lower edge
    assert targets[1] == m.deformation_for(-5000)
    assert targets[2] == m.deformation_for(-5000 - h) and targets[0] == m.deformation_for(-5000 + h)
    return {"seen": seen, "targets": list(targets)}


def case_ring():
    from firmware.telemetry import RECORD_WORDS, Ring

    r = Ring(4)
    r.every = 1
    dst = array("i", [0] * RECORD_WORDS)
    assert not r.read_into(dst)
    rec = array("i", [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, -11])  # a negative word comes back as it went
    i = 0
    while i < 6:
        rec[0] = i
        assert r.push(rec)
        i += 1
    got = []
    while r.read_into(dst):
        got.append(dst[0])
        assert list(dst[1:]) == list(range(1, 11)) + [-11]
    assert got == [2, 3, 4, 5] and r.dropped == 2, (got, r.dropped)
    r.every = 3
    kept = [r.push(rec) for _ in range(9)]
    assert kept == [False, False, True] * 3, kept
    return {"dropped": r.dropped}


def case_board_files():
    """Every shipped board file loads; broken ones fail with a reason a user can act on."""
    from firmware.board_config import BoardError, check_board, load_board

    names = []
    for name in ("pico", "esp32_devkitc", "pyboard", "sim"):
        b = load_board("boards/%s.json" % name)
        assert b["loop_hz"] == 1000 and b["adc_bits"] == 12 and b["sources"], name
        names.append(b["name"])
    reasons = []
    for broken in (
        {"name": "x", "adc_bits": 12, "adc_pins": {"pot1": 1}, "driver": "two_pwm", "motor_pins": {"in1": 2, "in2": 3}},
        {"name": "x", "adc_bits": 12, "adc_pins": {"pot1": 1, "pot2": 2}, "driver": "l298", "motor_pins": {}},
        {"name": "x", "adc_bits": 12, "adc_pins": {"pot1": 1, "pot2": 2}, "driver": "pwm_dir", "motor_pins": {"pwm": 4}},
        {"name": "x", "adc_bits": 24, "adc_pins": {"pot1": 1, "pot2": 2}, "driver": "two_pwm", "motor_pins": {"in1": 2, "in2": 3}},
    ):
        try:
            check_board(broken)
            raise AssertionError("accepted a broken board %r" % broken)
        except BoardError as exc:
            reasons.append(str(exc))
    assert "pot2" in reasons[0] and "l298" in reasons[1] and "dir" in reasons[2] and "adc_bits" in reasons[3], reasons
    try:
        load_board("boards/no_such_board.json")
        raise AssertionError("missing board file accepted")
    except BoardError as exc:
        assert "not found" in str(exc)
    return {"boards": names, "reasons": reasons}


def case_boot_survives_any_calibration(path, bad_paths):
    """Every file in bad_paths as the calibration: the App boots, motor off, no calibration,
    and says why; open loop still works."""
    from firmware.app import App

    whys = []
    for bad in bad_paths:
        app = App("boards/sim.json", bad, machine=ReplayMachine({"pot1": [32000], "pot2": [32000], "reference": [32000], "gauge": [32000]}))
        st = app.status()
        assert st["calibration_crc"] is None and st["calibration_error"], st
        assert pwm_duties(app) == [0, 0]
        app.set_mode("open_loop")
        app.set_target(1000)
        whys.append(st["calibration_error"])
    return {"why": whys}


def case_calibrations_the_board_refuses(path):
    """A pot table whose positions fall as the code rises, and a calibration made for another
    board: both refused with the reason; closed loop refused, open loop still works."""
    data = load(path)
    app, _ = replay_app(data)
    whys = []
    for cal in (load_calibration(data, "falling"), load_calibration(data, "other_board")):
        app.set_calibration(cal)
        st = app.status()
        assert st["calibration_crc"] is None and st["calibration_error"], st
        try:
            app.set_mode("position")
            raise AssertionError("closed loop accepted")
        except ValueError:
            pass
        app.set_mode("open_loop")
        app.set_mode("idle")
        whys.append(st["calibration_error"])
    assert "falls" in whys[0] and "pico" in whys[1], whys
    return {"why": whys}


def case_stroke_limits_from_end_stops(path):
    """The soft limits in force: the parameters, kept stop_margin_um inside the end stops the
    calibration measured (its stroke section); a negative margin (calibration sweeps) lets the
    parameters alone decide; without end stops the parameters alone decide."""
    data = load(path)
    app, _ = replay_app(data)
    out = {"none": app.status()["stroke_um"], "stops_none": app.status()["end_stops_um"]}
    for name, stops in (("low_shifted", [-2000, 58000]), ("high_shifted", [1000, 61000])):
        app.set_calibration(load_calibration(data, "stroke_" + name))  # end stops at `stops`
        st = app.status()
        assert st["calibration_error"] is None and st["end_stops_um"] == stops, st
        out[name] = st["stroke_um"]
    app.set_param("stroke_min_um", 2000)  # a parameter inside the stops wins
    out["param_inside"] = app.status()["stroke_um"]
    app.set_param("stop_margin_um", -65535)  # a sweep opens them to the parameters
    out["margin_open"] = app.status()["stroke_um"]
    app.set_param("stroke_min_um", -65535)
    app.set_param("stroke_max_um", 65535)
    out["all_open"] = app.status()["stroke_um"]
    app.set_calibration(load_calibration(data))  # a calibration without end stops forgets them
    out["forgotten"] = app.status()["end_stops_um"]
    return out


def case_force_targets_within_the_range_held(path):
    """Force mode takes targets within the forces the calibration held (its force_range section)
    and refuses one beyond them, saying the range, with the target it had kept; a calibration
    without the section takes any target the protocol allows."""
    data = load(path)
    app, _ = replay_app(data, calibration="force_range")
    out = {"range": app.status()["force_range_mN"]}
    app.set_mode("force")
    accepted = []
    for target in (-12500, 14000, 3000):
        app.set_target(target)
        accepted.append(app.status()["target"])
    out["accepted"] = accepted
    refused = []
    for target in (-12501, 14001, -150000):
        try:
            app.set_target(target)
            refused.append(None)
        except ValueError as exc:
            refused.append(str(exc))
    out["refused"] = refused
    out["kept"] = app.status()["target"]
    app.set_mode("idle")
    app.set_calibration(load_calibration(data))  # no force_range: only the protocol's +-200 N
    app.set_mode("force")
    app.set_target(-150000)
    out["without"] = [app.status()["force_range_mN"], app.status()["target"]]
    app.set_mode("idle")
    return out


def case_calibrations_for_another_adc_width(path, bcm3_path):
    """Pot constants exported for another ADC width than the board's are refused with the reason
    before any curve is evaluated: a 10-bit table, and a bcm3 with input shift 0, which declares
    29 bits (the boot would evaluate all 2**29 codes first: hours on a Cortex-M0, the board
    silent meanwhile). Open loop still works."""
    data = load(path)
    whys = []
    narrow = load_calibration(data, "narrow")  # pwl tables with input shift 6: a 10-bit ADC
    wide = load_calibration(load(bcm3_path), "wide")  # bcm3 with input shift 0: a 29-bit ADC
    assert narrow.pot1[0] == "pwl" and narrow.pot1[1][1] == 6 and wide.pot1[0] == "bcm3" and wide.pot1[1][0] == 0
    from firmware.bcm_fixed import invalid

    assert invalid(wide.pot1[1]) is None  # still a valid bcm3 layout
    app, _ = replay_app(data)
    for cal in (narrow, wide):
        app.set_calibration(cal)
        st = app.status()
        assert st["calibration_crc"] is None, st
        whys.append(st["calibration_error"])
        app.set_mode("open_loop")
        app.set_mode("idle")
    assert "10-bit ADC" in whys[0] and "29-bit ADC" in whys[1] and "12-bit" in whys[1], whys
    return {"why": whys}


def case_df_table(path, codes):
    """D1* of pot 1's codes with the calibration file at `path`, whose Df is a table (df_kind pwl):
    [D1*, D1] per code, as the board's per-code table holds them."""
    from firmware.calibration import load_calibration as load_file
    from firmware.measurement import Measurement

    m = Measurement(load_file(path))
    return [[m._d1(m.conv1(c, m.k1)), m.conv1(c, m.k1)] for c in codes]
