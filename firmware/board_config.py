"""Board description: read the board JSON at boot, fill the defaults, reject what cannot work.

The keys are listed in docs/firmware.md and boards/README.md. Errors are BoardError with a
reason a user can act on (the board file is the user's to edit).
"""

import json

DEFAULTS = {"loop_hz": 1000, "oversample": 4, "pwm_freq": 20000, "supply_volts": 5.0}
REQUIRED = ("name", "adc_bits", "adc_pins", "driver", "motor_pins")
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
    return board


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
