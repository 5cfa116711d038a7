"""Results that compare bit for bit across CPython and MicroPython (runs under both).

A case's or a program's result is printed as one `RESULT <json>` line with every float written as
the hex of its IEEE 754 double, so the two interpreters' results are equal exactly when their
numbers are; `decode` (CPython) turns such a value back into floats.
"""

import binascii
import json
import struct

PREFIX = "RESULT "


def _has_float(v):
    if isinstance(v, float):
        return True
    if isinstance(v, (list, tuple)):
        for x in v:
            if _has_float(x):
                return True
    elif isinstance(v, dict):
        for x in v.values():
            if _has_float(x):
                return True
    return False


def encode(v):
    """`v` with its floats as hex strings; a part without floats is returned as it is (a large
    result of integers is not copied: the board-sized heap of a MicroPython run may not hold two)."""
    if isinstance(v, float):
        return "f" + binascii.hexlify(struct.pack("<d", v)).decode()
    if not _has_float(v):
        return v
    if isinstance(v, (list, tuple)):
        return [encode(x) for x in v]
    return dict((k, encode(x)) for k, x in v.items())


def emit(v):
    """Print `v` as the one result line."""
    print(PREFIX + json.dumps(encode(v)))


def decode(v):
    if isinstance(v, str) and v.startswith("f") and len(v) == 17:
        return struct.unpack("<d", bytes.fromhex(v[1:]))[0]
    if isinstance(v, list):
        return [decode(x) for x in v]
    if isinstance(v, dict):
        return {k: decode(x) for k, x in v.items()}
    return v


def result(stdout):
    """The decoded value of the one result line in a program's output."""
    lines = [ln for ln in stdout.splitlines() if ln.startswith(PREFIX)]
    assert len(lines) == 1, stdout
    return decode(json.loads(lines[0][len(PREFIX):]))


def plain(v):
    """`v` as the other interpreter's result would arrive: through the same encoding and JSON."""
    return decode(json.loads(json.dumps(encode(v))))
