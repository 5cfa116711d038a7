"""The board's interface, one definition for both sides: the version, the command set with each
argument's kind, the modes, the parameter table, the telemetry record and the frame layout.

The firmware's link dispatches commands from COMMANDS (firmware/link.py), the App checks
parameters against PARAMS, the host formats and checks its command lines with the same table
(host/link/board_client.py), and docs/protocol.md is generated from this module
(host/link/protocol_doc.py, kept current by a test).

The board's USB serial port also carries the MicroPython REPL, so:
- host -> board: one ASCII line per command, `!<seq> <cmd> <args...> *<crc32 hex>\\n`, where the
  CRC32 covers the text before ` *`. Lines never contain Ctrl-C (0x03) or Ctrl-D (0x04), so
  mpremote can always break in.
- board -> host: binary frames, all 32-bit little-endian words so the firmware can build them in
  a preallocated array without packing bytes:
    word 0: 0xA5 0x5A <type> <count>   (sync marker, frame type, records in a telemetry frame)
    word 1: payload length in bytes
    word 2: sequence number (16 bits; replies echo the command's, telemetry counts its frames)
    payload (length bytes, padded with zeros to a whole word)
    CRC32 of everything before it (binascii.crc32)
  The host decoder skips anything that is not a valid frame (REPL text, banners, noise).
"""

import binascii
import struct

from firmware.pi_control import DUTY_MAX, GAIN_MAX
from firmware.telemetry import RECORD_WORDS

VERSION = "0.1.0"  # the firmware's, and the host package's (pyproject.toml reads it from here)
PROTOCOL_VERSION = 1
SYNC = b"\xa5\x5a"
# A text line the firmware prints as its boot begins, before the calibration's checks and tables
# (about a second on an RP2040): a host that sees it after a reset waits for the hello instead of
# taking the silence for a board without our firmware
BOOTING = "lsea-kit booting"
SYNC_WORD = 0x5AA5  # the two sync bytes read as the low half of little-endian word 0
HEADER_FORMAT = "<BBBBII"  # word 0's four bytes (sync 0xA5 0x5A, type, count), the payload length, the sequence
HEADER_BYTES = 12  # struct.calcsize(HEADER_FORMAT)
CRC_BYTES = 4
MAX_PAYLOAD = 1024  # bounds how long a corrupted length field can hold up the decoder
SEQ_MASK = 0xFFFF
MAX_LINE = 200  # longest command line the board accepts (its preallocated line buffer)
TOKEN_MIN = 0x21  # the bytes a command word may hold: printable ASCII, no space, so no Ctrl-C/D
TOKEN_MAX = 0x7E
TELEMETRY_BATCH = 16  # most records in one telemetry frame
POSITION_LIMIT_UM = 65535  # positions are whole um within +-this (measurement clamps to it): strokes within +-65.5 mm
INT_LIMIT = 1 << 30  # integer arguments stay within +-2**30, the small-int range of 32-bit boards

# Modes, by number (the `mode` telemetry field; firmware/controller.py's IDLE .. FORCE)
MODES = ("idle", "open_loop", "position", "force")

# The controller's parameters: name, default, min, max, unit. The limits keep every intermediate
# of the step within +-2**30 (firmware/controller.py, pi_control.py); docs/firmware.md says what
# each one does. Their order is the index the step reads them by (controller.P_KP_POS ...).
PARAMS = (
    ("kp_pos", 768, 0, GAIN_MAX, "duty/256 per um"),  # Q8 duty per um of position error
    ("ki_pos", 16, 0, GAIN_MAX, "duty/256 per um per step"),  # into the Q8 integral
    ("kp_force", 2560, 0, GAIN_MAX, "duty/256 per um"),  # per um of deformation error
    ("ki_force", 8192, 0, GAIN_MAX, "duty/256 per um per step"),
    ("out_limit", 8000, 0, DUTY_MAX, "duty"),  # |PI output| limit (duty 10000 = 100 %)
    ("int_limit", 8000, 0, DUTY_MAX, "duty"),  # |integral| limit: out_limit, so a held force or position can use all of the duty the output may
    ("slew", 500, 0, DUTY_MAX, "duty per step"),  # max duty change per step (0 = unlimited)
    ("host_timeout_ms", 1000, 0, 600000, "ms"),  # host silence that stops the motor (0 = off)
    ("rail_reads", 4, 1, 1000, "reads"),  # consecutive reads at a rail that make a fault
    ("rail_margin", 0, 0, 255, "codes"),  # codes from the rail that count as "at the rail"
    ("stroke_min_um", 500, -POSITION_LIMIT_UM, POSITION_LIMIT_UM, "um"),  # soft stroke limits on the block's position D2
    ("stroke_max_um", 59500, -POSITION_LIMIT_UM, POSITION_LIMIT_UM, "um"),
    ("slow_zone_um", 5000, 1, 65535, "um"),  # |duty| toward a limit is capped, falling to 0 over this
    ("defl_rate_um", 2, 0, 65535, "um per step"),  # force mode: the deformation setpoint moves at most this per step (0 = jump)
    ("stop_margin_um", 300, -POSITION_LIMIT_UM, POSITION_LIMIT_UM, "um"),  # the soft limits stay this far inside the calibrated end stops
    ("pos_deadband_um", 8, 0, 20000, "um"),  # position mode with friction feed-forward: parked (no push, no integration) inside this, until 3x it
)
PARAM_NAMES = tuple(row[0] for row in PARAMS)

T_US_WRAP = 1 << 30  # the records' t_us (and the step counter) wrap here: 31-bit small ints on every board

# The telemetry record: RECORD_WORDS int32 words, in this order (firmware/telemetry.py's ring)
FIELDS = (
    "t_us",  # loop time since start, us (step count x period, wraps at 2**30)
    "raw1",  # pot 1 code, board-native bits, oversampled mean
    "raw2",  # pot 2 code
    "raw_ref",  # reference channel code (0 when the board has none)
    "d1_um",  # nut position D1* (after the Df correction), um
    "d2_um",  # output block position D2, um
    "defl_um",  # spring deformation d = D1* - D2, um
    "force_mN",  # F0(d), mN
    "target",  # the mode's target: duty, um or mN
    "duty",  # signed duty sent to the bridge, [-DUTY_MAX, DUTY_MAX]
    "mode",  # mode number (MODES)
    "faults",  # fault bit mask (FAULT_NAMES)
)
# Each field's unit, in FIELDS' order (what they mean, for people: host/link/telemetry_log.py UNITS)
FIELD_UNITS = ("us", "code", "code", "code", "um", "um", "um", "mN", "duty, um or mN", "duty", "mode", "fault bits")

# Fault bits and their names (firmware/safety.py's FAULT_* constants are these bits: tested equal)
FAULT_NAMES = (
    (1, "rail_pot1"),
    (2, "rail_pot2"),
    (4, "host_timeout"),
    (8, "step_exception"),
    (16, "interrupted"),
    (32, "run_exception"),
    (64, "soft_reset"),
)

# The keys of the `status` object (firmware/app.py App.status; tested equal), in host status's order
STATUS_KEYS = ("version", "protocol", "board", "calibration_crc", "calibration_error", "mode", "faults", "last_fault",
               "target", "duty", "stroke_um", "end_stops_um", "force_range_mN", "params_changed", "params_saved", "params_file_error",
               "params_restored", "params_temporary", "steps", "period_us", "step_us_max", "overruns", "timer",
               "interpreter", "mpy", "last_exit", "interface")

# Frame types: (number, name); what each payload holds is in docs/protocol.md
T_OK = 1
T_ERROR = 2
T_TELEMETRY = 3
T_HELLO = 4
FRAME_TYPES = ((T_OK, "ok"), (T_ERROR, "error"), (T_TELEMETRY, "telemetry"), (T_HELLO, "hello"))
TYPE_NAMES = {number: name for number, name in FRAME_TYPES}

# The kinds of a command's arguments: INT, a decimal integer within +-INT_LIMIT, or a tuple of the
# words accepted. Each argument is (name, kind, default); REQUIRED as the default means it must be
# given, any other default is used when it is not.
INT = "int"
REQUIRED = None
# Commands: name, arguments, the App method that runs it, and whether it runs after its reply is
# sent (reset: the reply must leave before the state it reports is gone). What each one does and
# returns is written for people in host/link/protocol_doc.py (kept off the board, where every
# string costs heap), which fails when a command here has no text there.
COMMANDS = (
    ("status", (), "status", False),
    ("stop", (), "stop", False),
    ("mode", (("name", MODES, REQUIRED),), "set_mode", False),
    ("target", (("value", INT, REQUIRED),), "set_target", False),
    ("stream", (("state", ("on", "off"), REQUIRED), ("hz", INT, 1000)), "stream", False),
    ("get", (("param", PARAM_NAMES, REQUIRED),), "get_param", False),
    ("set", (("param", PARAM_NAMES, REQUIRED), ("value", INT, REQUIRED), ("temp", ("temp",), False)), "set_param", False),
    ("params", (), "params", False),
    ("save", (), "save_params", False),
    ("heartbeat", (), "heartbeat", False),
    ("reset", (), "reset", True),
)
COMMAND_NAMES = tuple(c[0] for c in COMMANDS)
_BY_NAME = {c[0]: c for c in COMMANDS}


class ProtocolError(Exception):
    """A command line that cannot be accepted; args = (seq or -1, message)."""


def crc32(data):
    return binascii.crc32(data) & 0xFFFFFFFF


def interface_text():
    """This table as one line of text, the same on every interpreter: what the board and the host
    must agree on (the frame layout, the telemetry record, the modes, faults, commands and
    parameters). Built from ints and strings only, so CPython and MicroPython write it alike."""

    def words(items):
        return ",".join(str(x) for x in items)

    parts = ["v%d" % PROTOCOL_VERSION, words((SYNC_WORD, HEADER_BYTES, CRC_BYTES, MAX_PAYLOAD, SEQ_MASK, MAX_LINE,
                                              TELEMETRY_BATCH, INT_LIMIT, RECORD_WORDS)),
             words(FIELDS), words(FIELD_UNITS), words(MODES), words("%d=%s" % t for t in FRAME_TYPES),
             words("%d=%s" % t for t in FAULT_NAMES), words(STATUS_KEYS)]
    for name, args, _method, _after in COMMANDS:
        parts.append("%s(%s)" % (name, words("%s:%s=%s" % (a[0], a[1] if a[1] == INT else "|".join(a[1]), a[2])
                                              for a in args)))
    for row in PARAMS:
        parts.append(words(row))
    return ";".join(parts)


def interface_hash():
    """The CRC32 of interface_text, as 8 hex digits: `hello` and `status` carry it, and the host
    refuses a board whose table is not its own (a firmware from another checkout) in one line."""
    return "%08x" % binascii.crc32(interface_text().encode())  # unsigned on both interpreters; at boot, not in the step


def _token_problem(token):
    """Why `token` cannot be one word of a command line, or None when it can."""
    if not token:
        return "is empty"
    for c in token:
        n = ord(c)
        if n == 3 or n == 4:
            return "contains Ctrl-%s (0x%02x), which would break into the board's REPL" % ("C" if n == 3 else "D", n)
        if n > TOKEN_MAX:
            return "is not ASCII" if n > 0x7F else "contains a control character (0x7f)"
        if n == 0x20 or c.isspace():
            return "contains whitespace (0x%02x), which would split it in two" % n
        if n < TOKEN_MIN:
            return "contains a control character (0x%02x)" % n
    return None


def format_command(seq, name, *args):
    """The bytes of one command line (host side).

    Every word (the command and each str(arg)) must be printable ASCII without spaces
    (TOKEN_MIN..TOKEN_MAX), so a line never carries Ctrl-C/Ctrl-D to the REPL and parses back to
    the same words; anything else, or a line longer than MAX_LINE, raises ValueError."""
    words = [str(name)] + [str(a) for a in args]
    for i, word in enumerate(words):
        why = _token_problem(word)
        if why:
            what = "command name" if i == 0 else "argument %d of %s" % (i, words[0][:24])
            raise ValueError("%s %r %s: command words must be printable ASCII without spaces" % (what, word[:40], why))
    text = "!%d %s" % (seq & SEQ_MASK, " ".join(words))
    line = ("%s *%08x\n" % (text, crc32(text.encode()))).encode()
    if len(line) - 1 > MAX_LINE:
        raise ValueError("command line of %d bytes is longer than the board's %d" % (len(line) - 1, MAX_LINE))
    return line


def parse_command(line):
    """Parse one line (bytes, without the newline) -> (seq, name, argument values), the values
    read by their kinds in COMMANDS (int for INT, the word for a choice), defaults filled in.

    Raises ProtocolError(seq, message) for anything else; seq is -1 when it cannot be read.
    """
    if len(line) > MAX_LINE:
        raise ProtocolError(-1, "line too long")
    try:
        text = line.decode()
    except Exception:
        raise ProtocolError(-1, "line is not ASCII")
    text = text.strip()
    star = text.rfind(" *")
    if not text.startswith("!") or star < 0:
        raise ProtocolError(-1, "expected !<seq> <cmd> <args> *<crc32>")
    body = text[:star]
    parts = body[1:].split()
    seq = -1
    if parts:
        try:
            seq = int(parts[0]) & SEQ_MASK
        except ValueError:
            seq = -1
    try:
        crc = int(text[star + 2 :], 16)
    except ValueError:
        raise ProtocolError(seq, "bad checksum field")
    if crc != crc32(body.encode()):
        raise ProtocolError(seq, "checksum mismatch")
    if seq < 0 or len(parts) < 2:
        raise ProtocolError(seq, "expected !<seq> <cmd> <args> *<crc32>")
    try:
        return seq, parts[1], arguments(parts[1], parts[2:])
    except ValueError as exc:
        raise ProtocolError(seq, str(exc))


def command_row(name):
    """The COMMANDS row of `name`; ValueError for a command the board does not have."""
    row = _BY_NAME.get(name)
    if row is None:
        raise ValueError("unknown command " + str(name)[:24])
    return row


def arguments(name, words):
    """The values of command `name`'s arguments from their words (str on the board; the host's
    values on the host), each read and checked as its kind says, defaults filled in; ValueError
    says what is wrong."""
    spec = command_row(name)[1]
    if len(words) > len(spec):
        raise ValueError("%s takes at most %d arguments" % (name, len(spec)))
    values = []
    for i, (arg, kind, default) in enumerate(spec):
        if i >= len(words):
            if default is REQUIRED:
                raise ValueError("%s needs %s" % (name, " ".join(a[0] for a in spec if a[2] is REQUIRED)))
            values.append(default)
        elif kind == INT:
            values.append(parse_int(words[i]))
        elif words[i] in kind:
            values.append(words[i])
        else:
            raise ValueError("%s: %s must be one of %s, not %s" % (name, arg, ", ".join(kind), str(words[i])[:24]))
    return values


def parse_int(token):
    """A command's integer argument, kept inside the board's small-int range."""
    if isinstance(token, bool):
        raise ValueError("not an integer: %s" % (token,))
    try:
        value = int(token)
    except ValueError:
        raise ValueError("not an integer: " + str(token)[:24])
    if isinstance(token, float) or not -INT_LIMIT <= value <= INT_LIMIT:
        raise ValueError("out of range: " + str(token)[:24])
    return value


def padded(n):
    return (n + 3) & ~3


def encode_frame(ftype, seq, payload=b"", count=0):
    """One complete frame as bytes (replies and hello; telemetry uses the preallocated path)."""
    n = len(payload)
    if n > MAX_PAYLOAD:
        raise ValueError("payload too long")
    head = struct.pack(HEADER_FORMAT, SYNC[0], SYNC[1], ftype, count, n, seq & SEQ_MASK)
    body = head + payload + bytes(padded(n) - n)
    return body + struct.pack("<I", crc32(body))


def telemetry_frame_words(count):
    """Words in a telemetry frame carrying `count` records (header, dropped, records, CRC)."""
    return 3 + 1 + count * RECORD_WORDS + 1
