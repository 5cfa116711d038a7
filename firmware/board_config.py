"""Board description: read the board JSON at boot, fill the defaults, reject what cannot work.

The keys are listed in docs/firmware.md and boards/README.md. Errors are BoardError with a
reason a user can act on (the board file is the user's to edit).
"""

import json

from firmware.protocol import POSITION_LIMIT_UM

DEFAULTS = {"loop_hz": 1000, "oversample": 4, "pwm_freq": 20000, "supply_volts": 5.0}
REQUIRED = ("name", "adc_bits", "adc_pins", "driver", "motor_pins")
TIMER_APIS = ("machine", "pyb")
# The clock a loop timer counts its period in, when the board file does not say: the 1 ms soft
# timer (machine.Timer(-1) on stm32 and others), or the simulated board's microsecond timer.
DEFAULT_TICK_HZ = 1000
SIM_TICK_HZ = 1000000
DRIVER_PINS = {"two_pwm": ("in1", "in2"), "pwm_dir": ("pwm", "dir")}


class BoardError(Exception):
    pass


def check_board(board):
    """Validate a board dict in place (defaults filled in) and return it."""
    for key in REQUIRED:
        if key not in board:
            raise BoardError("board file has no %r" % key)
    for key, value in DEFAULTS.items():
        board.setdefault(key, value)
    if not 8 <= board["adc_bits"] <= 16:
        raise BoardError("adc_bits must be 8..16, not %r" % board["adc_bits"])
    for pot in ("pot1", "pot2"):
        if pot not in board["adc_pins"]:
            raise BoardError("adc_pins has no %r" % pot)
    invert = board.setdefault("pot_invert", [])
    if not isinstance(invert, list) or any(p not in ("pot1", "pot2") for p in invert):
        raise BoardError("pot_invert must be a list of pot1/pot2, not %r" % (invert,))
    need = DRIVER_PINS.get(board["driver"])
    if need is None:
        raise BoardError("driver must be two_pwm or pwm_dir, not %r" % board["driver"])
    for pin in need:
        if pin not in board["motor_pins"]:
            raise BoardError("driver %s needs motor_pins[%r]" % (board["driver"], pin))
    if not 10 <= board["loop_hz"] <= 10000:
        raise BoardError("loop_hz must be 10..10000, not %r" % board["loop_hz"])
    if not 1 <= board["oversample"] <= 64:
        raise BoardError("oversample must be 1..64, not %r" % board["oversample"])
    check_timer(board)
    check_stroke(board)
    return board


STROKE_LIMIT_MM = (POSITION_LIMIT_UM // 100) / 10.0  # 65.5: a stroke's ends in mm, within the positions the board represents


def check_stroke(board):
    """"stroke_mm": [low, high], the actuator's nominal stroke (optional; 0-60 mm without it). The
    soft stroke limits start 0.5 mm inside it, and the host's calibration and experiments follow
    it (host/guided/stroke.py)."""
    stroke = board.get("stroke_mm")
    if stroke is None:
        return
    ok = isinstance(stroke, list) and len(stroke) == 2 and all(isinstance(v, (int, float)) for v in stroke)
    if not ok or not -STROKE_LIMIT_MM <= stroke[0] < stroke[1] <= STROKE_LIMIT_MM:
        raise BoardError("stroke_mm must be [low, high] in mm within +-%s (low < high), not %r" % (STROKE_LIMIT_MM, stroke))


def check_timer(board):
    """The loop timer: a known API, and a loop_hz it can produce exactly.

    A timer counts its period in whole ticks of `timer_tick_hz` (1 ms soft timers: 1000; rp2's
    microsecond alarms: 1000000; esp32 hardware timers: 80 MHz / 8; pyb.Timer 4: 84 MHz), so
    loop_hz must divide it: a 1 ms timer asked for 1500 Hz runs every 0 or 1 ms, not 0.667 ms.
    The step's telemetry clock adds 1000000 // loop_hz us per step, so loop_hz must divide 10**6
    as well, or the record timestamps drift from the real time.
    """
    api = board.setdefault("timer_api", "machine")
    if api not in TIMER_APIS:
        raise BoardError("timer_api must be machine or pyb, not %r" % (api,))
    hard = board.get("timer_hard")
    if hard is not None and hard is not True and hard is not False:
        raise BoardError("timer_hard must be true or false, not %r" % (hard,))
    if api == "pyb":
        tid = board.get("timer_id")
        if not isinstance(tid, int) or tid < 1:
            raise BoardError("timer_api pyb needs timer_id, a pyb.Timer number (1..14), not %r" % (tid,))
        if hard is not None:
            raise BoardError("timer_hard does not apply to timer_api pyb (pyb.Timer callbacks are hard IRQs)")
    tick = board.setdefault("timer_tick_hz", SIM_TICK_HZ if board.get("simulated") else DEFAULT_TICK_HZ)
    if not isinstance(tick, int) or tick < 1:
        raise BoardError("timer_tick_hz must be a positive integer (Hz), not %r" % (tick,))
    hz = board["loop_hz"]
    if tick % hz:
        raise BoardError(
            "loop_hz %d is not a whole number of timer ticks: the timer counts at %d Hz "
            "(timer_tick_hz), so a period of %d/%d ticks cannot be made; use a loop_hz that "
            "divides %d" % (hz, tick, tick, hz, tick)
        )
    if 1000000 % hz:
        raise BoardError(
            "loop_hz %d does not divide 1000000: the telemetry clock counts whole microseconds "
            "per step" % hz
        )


def load_board(path):
    try:
        with open(path) as f:
            board = json.load(f)
    except OSError:
        raise BoardError("board file %s not found" % path)
    except ValueError as exc:
        raise BoardError("board file %s is not valid JSON (%s)" % (path, exc))
    if not isinstance(board, dict):
        raise BoardError("board file %s must hold a JSON object" % path)
    return check_board(board)
