"""`host status`: what the board runs and its state, every field the firmware reports."""

import json

from firmware.protocol import STATUS_KEYS
from host.commands._options import add_port_arguments, open_board
from host.errors import DONE
from host.terminal import output

# how each key of firmware/protocol.py STATUS_KEYS is shown, in that order (a test checks every key
# has its label); a field a newer firmware adds follows as it is
LABELS = {
    "version": "firmware version",
    "protocol": "protocol",
    "board": "board",
    "calibration_crc": "calibration CRC",
    "calibration_error": "calibration problem",
    "mode": "mode",
    "faults": "latched faults",
    "last_fault": "last fault",
    "target": "target",
    "duty": "duty (of 10000)",
    "stroke_um": "soft stroke limits on D2 (um)",
    "end_stops_um": "block's end stops in D2 (um)",
    "force_range_mN": "force targets held (mN)",
    "params_changed": "parameters changed since boot",
    "params_saved": "saved parameters (boot values)",
    "params_file_error": "saved parameters problem",
    "params_restored": "parameters restored",
    "params_temporary": "temporary parameters",
    "steps": "steps since boot (mod 2**30)",
    "period_us": "loop period (us)",
    "step_us_max": "longest step (us)",
    "overruns": "overruns",
    "timer": "loop timer",
    "interpreter": "interpreter",
    "mpy": ".mpy version word",
    "last_exit": "last exit",
    "interface": "interface",
}


def add_parser(subparsers):
    p = subparsers.add_parser(
        "status", help="show the board's firmware, calibration, mode, faults and loop timing",
        description="Every field the firmware reports. 'longest step' and 'overruns' come from the board's "
        "own clock: overruns count steps that started 1.5 periods late or ran a whole period (docs/firmware.md).")
    add_port_arguments(p)
    p.add_argument("--json", action="store_true", help="print the firmware's status object as JSON")
    p.set_defaults(func=run)


def describe(status):
    """The status as 'label: value' lines for a person."""
    lines = []
    seen = set()
    for key in STATUS_KEYS:
        if key not in status:
            continue
        label = LABELS[key]
        seen.add(key)
        value = status[key]
        if key == "calibration_crc" and value is not None:
            value = "%08x" % (value & 0xFFFFFFFF)
        elif key == "faults":
            value = ", ".join(value) if value else "none"
            if status.get("faults"):
                value += "  (host reset clears them)"
        elif key in ("stroke_um", "end_stops_um", "force_range_mN") and value:
            value = "%s .. %s" % tuple(value)
        elif key in ("params_changed", "params_temporary"):
            value = ", ".join(value) if value else "none"
        elif key == "params_saved" and value is not None:
            value = ", ".join("%s=%d" % kv for kv in sorted(value.items())) or "all defaults"
        elif key == "force_range_mN" and value is None and status.get("calibration_crc") is not None:
            value = "not in the calibration (any target within +-200000 mN)"
        if value is None:
            value = "none"
        lines.append("%-30s %s" % (label, value))
    for key in sorted(k for k in status if k not in seen):
        lines.append("%-30s %s" % (key, status[key]))
    return lines


def run(args):
    with open_board(args) as board:
        status = board.status()
    if args.json:
        crc = status.get("calibration_crc")
        if crc is not None:  # hex, as host flash, host show and the log's metadata write it
            status = dict(status, calibration_crc="%08x" % (crc & 0xFFFFFFFF))
        output(json.dumps(status, indent=1, sort_keys=True))
    else:
        output("\n".join(describe(status)))
    return DONE
