"""The host-board protocol: the one source of truth of the message set, shared by both sides.

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

Imported by firmware/link.py (board side), host/frames.py, host/board_client.py and
host/protocol_doc.py (which renders docs/protocol.md from COMMANDS, FRAME_TYPES and FIELDS).
"""

import binascii
import struct

from firmware.telemetry import FIELDS, RECORD_WORDS

PROTOCOL_VERSION = 1
SYNC = b"\xa5\x5a"
SYNC_WORD = 0x5AA5  # the two sync bytes read as the low half of little-endian word 0
HEADER_BYTES = 12
CRC_BYTES = 4
MAX_PAYLOAD = 1024  # bounds how long a corrupted length field can hold up the decoder
SEQ_MASK = 0xFFFF
MAX_LINE = 200  # longest command line the board accepts (its preallocated line buffer)
TOKEN_MIN = 0x21  # the bytes a command word may hold: printable ASCII, no space, so no Ctrl-C/D
TOKEN_MAX = 0x7E
TELEMETRY_BATCH = 16  # most records in one telemetry frame

# Frame types: (number, name, payload description)
T_OK = 1
T_ERROR = 2
T_TELEMETRY = 3
T_HELLO = 4
FRAME_TYPES = (
    (T_OK, "ok", "UTF-8 JSON value: the command's result (null when it has none)"),
    (T_ERROR, "error", "UTF-8 text: why the command was refused or failed"),
    (
        T_TELEMETRY,
        "telemetry",
        "int32 `dropped` (records the board's ring overwrote before they were sent, cumulative), "
        "then `count` records of %d int32 each, fields in the order of FIELDS" % RECORD_WORDS,
    ),
    (T_HELLO, "hello", "UTF-8 JSON object sent once when the firmware starts: version, board, protocol"),
)
TYPE_NAMES = {number: name for number, name, _ in FRAME_TYPES}

# Commands: (name, argument names, result, what it does). Arguments are printable ASCII tokens
# (TOKEN_MIN..TOKEN_MAX; format_command refuses anything else); integers are decimal. `int`
# arguments must fit +-2**30 (the board's small-int range).
COMMANDS = (
    ("status", (), "object: version, board, calibration crc/error, mode, faults, last_fault, target, duty, steps, "
     "step_us_max, overruns, period_us, stroke_um, end_stops_um, params_changed, params_saved, params_file_error, "
     "params_restored, params_temporary, timer, interpreter, mpy, last_exit, protocol",
     "identify the firmware and report its state (the handshake)"),
    ("stop", (), "null", "motor off, mode idle"),
    ("mode", ("name",), "null", "switch mode: idle, open_loop, position or force"),
    ("target", ("value:int",), "null",
     "set the target of the current mode: um (position), mN (force), signed duty (open_loop)"),
    ("stream", ("on/off", "[hz:int]"), "object: hz", "start telemetry at hz (default 1000) or stop it"),
    ("get", ("param",), "int", "read a controller parameter"),
    ("set", ("param", "value:int", "[temp]"), "null",
     "write a controller parameter; `temp`: for the command that sets it only, restored to its value before "
     "once the host is silent for host_timeout_ms (a plain `set` keeps it, and ends a temporary value)"),
    ("params", (), "list of [name, value, default, min, max, unit]",
     "the parameters `get`/`set` accept, with the values in force and their table"),
    ("save", (), "object: file, saved (names that differ from the defaults)",
     "keep the parameters in force on the board's filesystem; loaded at the next boot (idle only)"),
    ("heartbeat", (), "null", "keep-alive: the firmware stops the motor when heartbeats stop"),
    ("reset", (), "null", "clear latched faults, motor off, mode idle (after the reply is sent)"),
)
COMMAND_NAMES = tuple(c[0] for c in COMMANDS)
_ARITY = {c[0]: (sum(1 for a in c[1] if not a.startswith("[")), len(c[1])) for c in COMMANDS}


class ProtocolError(Exception):
    """A command line that cannot be accepted; args = (seq or -1, message)."""


def crc32(data):
    return binascii.crc32(data) & 0xFFFFFFFF


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
    """Parse one line (bytes, without the newline) -> (seq, name, args as list of str).

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
    name = parts[1]
    if name not in _ARITY:
        raise ProtocolError(seq, "unknown command " + name[:24])
    args = parts[2:]
    least, most = _ARITY[name]
    if not least <= len(args) <= most:
        raise ProtocolError(seq, "%s takes %d..%d arguments" % (name, least, most))
    return seq, name, args


def parse_int(token):
    """A command's integer argument, kept inside the board's small-int range."""
    try:
        value = int(token)
    except ValueError:
        raise ValueError("not an integer: " + token[:24])
    if not -(2**30) <= value <= 2**30:
        raise ValueError("out of range: " + token[:24])
    return value


def padded(n):
    return (n + 3) & ~3


def encode_frame(ftype, seq, payload=b"", count=0):
    """One complete frame as bytes (replies and hello; telemetry uses the preallocated path)."""
    n = len(payload)
    if n > MAX_PAYLOAD:
        raise ValueError("payload too long")
    head = struct.pack("<BBBBII", 0xA5, 0x5A, ftype, count, n, seq & SEQ_MASK)
    body = head + payload + bytes(padded(n) - n)
    return body + struct.pack("<I", crc32(body))


def telemetry_frame_words(count):
    """Words in a telemetry frame carrying `count` records (header, dropped, records, CRC)."""
    return 3 + 1 + count * RECORD_WORDS + 1
