"""The board side of the host link: command lines in from stdin, reply and telemetry frames out.

`Link(app)` is what `App.run` calls `poll()` on every main-loop iteration. `poll()` reads whatever
bytes stdin has (never blocking: select.poll with a zero timeout, one byte at a time so a read
can never wait for more), assembles lines in a preallocated bytearray, parses them with
firmware.protocol (each argument read as its kind in protocol.COMMANDS says), calls the App
method the table names for the command and answers with an ok or error frame. It then drains the
App's telemetry ring straight into a preallocated frame (the ring copies each record into a
memoryview slot of the frame, so draining allocates nothing) and writes it out.

The parser never raises: every line gets exactly one reply frame (error frames carry the reason).
KeyboardInterrupt (Ctrl-C from mpremote) is not caught, so it stops the App like on any board.
"""

import json
import sys

import binascii
import select

from firmware import protocol as P
from firmware.portable import zeros

_MAX_LINE = P.MAX_LINE
_BATCH = P.TELEMETRY_BATCH
_RW = P.RECORD_WORDS
_INPUT_PER_POLL = 256  # bytes of input handled per poll, so a flood cannot stall the loop


def _stdout_writer():
    out = getattr(sys.stdout, "buffer", sys.stdout)
    return out.write


class Link:
    """Serve the protocol for one App over a byte stream (stdin/stdout by default)."""

    def __init__(self, app, stdin=None, write=None):
        self.app = app
        self.write = write or _stdout_writer()
        # Poll sys.stdin itself (pollable on every port), read raw bytes from its buffer.
        self._pollable = stdin if stdin is not None else sys.stdin
        self._stdin = stdin if stdin is not None else getattr(sys.stdin, "buffer", sys.stdin)
        self._poller = None
        self._ipoll = None
        self._counts = hasattr(self._stdin, "in_waiting")
        self._line = bytearray(_MAX_LINE + 1)
        self._n = 0
        self._overflow = False
        self._byte = bytearray(1)
        self._last_line = b""
        self._last_reply = b""
        self._after_reply = None
        self.telemetry_seq = 0
        self.lines = 0
        self.errors = 0
        # int32 words, as the records are: CircuitPython refuses a negative value in an unsigned
        # array, and the ring copies the records in as they are (the CRC word is stored signed)
        frame = zeros(P.telemetry_frame_words(_BATCH), "i")
        view = memoryview(frame)
        self._frame = frame
        # One view per record slot (the ring copies into it) and, per record count, the span
        # the CRC covers and the whole frame: made once here so draining allocates nothing.
        self._slots = [view[4 + k * _RW : 4 + (k + 1) * _RW] for k in range(_BATCH)]
        self._crc_spans = [view[0 : P.telemetry_frame_words(k) - 1] for k in range(_BATCH + 1)]
        self._frames = [view[0 : P.telemetry_frame_words(k)] for k in range(_BATCH + 1)]

    # -- input -------------------------------------------------------------------------
    def poll(self):
        """One main-loop visit: handle pending input, then send pending telemetry."""
        self.read_input()
        self.send_telemetry()

    def read_input(self):
        byte = self._byte
        budget = _INPUT_PER_POLL
        while budget > 0 and self.waiting():
            if not self._stdin.readinto(byte):
                return
            self.feed_byte(byte[0])
            budget -= 1

    def waiting(self):
        """Input to read (App.run also asks it between passes of the main loop, at every
        wake-up: cheap, and allocation-free on MicroPython)."""
        if self._counts:  # a serial object that says how many bytes wait (CircuitPython's usb_cdc)
            return self._stdin.in_waiting > 0
        ipoll = self._ipoll
        if ipoll is None:
            if self._poller is None:
                self._poller = select.poll()
                self._poller.register(self._pollable, select.POLLIN)
                # MicroPython: ipoll yields the poller's own reused entry, so an idle main loop
                # that polls thousands of times a second makes no garbage
                self._ipoll = getattr(self._poller, "ipoll", None)
                return self.waiting()
            return bool(self._poller.poll(0))
        for _ in ipoll(0):
            return True
        return False

    def feed(self, data):
        """Handle a chunk of input bytes (used by tests and by read_input one byte at a time)."""
        for b in data:
            self.feed_byte(b)

    def feed_byte(self, b):
        if b == 10 or b == 13:
            if self._overflow:
                self._overflow = False
                self._n = 0
                self._reply(P.T_ERROR, -1, b"line too long")
            elif self._n:
                n = self._n
                self._n = 0
                self.handle_line(bytes(self._line[:n]))
            return
        if self._n >= _MAX_LINE:
            self._overflow = True
            return
        self._line[self._n] = b
        self._n += 1

    # -- commands ----------------------------------------------------------------------
    def handle_line(self, line):
        """Answer one command line with exactly one frame; never raises (except Ctrl-C)."""
        self.lines += 1
        if line == self._last_line and self._last_reply:
            # a retry of the command just done (its reply was lost): the same answer again, and
            # the host was heard, or a request whose replies got lost would look like silence
            self.app.heartbeat()
            self.write(self._last_reply)
            return
        seq = -1
        try:
            seq, name, values = P.parse_command(line)
            result = self.dispatch(name, values)
            frame = P.encode_frame(P.T_OK, seq, json.dumps(result).encode())
        except P.ProtocolError as exc:
            frame = self._error_frame(exc.args[0], exc.args[1])
        except Exception as exc:  # the App refused (ValueError) or failed: say why, keep going
            frame = self._error_frame(seq, self._describe(exc))
        self._last_line = line
        self._last_reply = frame
        self.write(frame)
        if self._after_reply is not None:  # now that its reply is out, before the next line is read
            method, values = self._after_reply
            self._after_reply = None
            method(*values)

    def _describe(self, exc):
        text = str(exc)
        name = type(exc).__name__
        if not text or name not in ("ValueError", "ProtocolError"):
            text = name + (": " + text if text else "")
        return text

    def _error_frame(self, seq, message):
        self.errors += 1
        return P.encode_frame(P.T_ERROR, seq, message.encode()[: P.MAX_PAYLOAD])

    def _reply(self, ftype, seq, payload):
        if ftype == P.T_ERROR:
            self.errors += 1
        self.write(P.encode_frame(ftype, seq, payload))

    def dispatch(self, name, values):
        """Run command `name` with its argument values: the App method protocol.COMMANDS names for
        it, now or, for a command that runs after its reply (reset), once the reply is out."""
        row = P.command_row(name)
        method = getattr(self.app, row[2])
        if row[3]:
            self._after_reply = (method, values)
            return None
        return method(*values)

    def hello(self):
        """Announce the firmware once at start (lets a host see a reboot happen)."""
        status = self.app.status()
        info = {"version": status["version"], "board": status["board"], "protocol": status["protocol"],
                "interface": status["interface"]}
        self.write(P.encode_frame(P.T_HELLO, 0, json.dumps(info).encode()))

    # -- telemetry ---------------------------------------------------------------------
    def send_telemetry(self, max_frames=8):
        """Drain the ring into frames of up to TELEMETRY_BATCH records; returns frames sent."""
        ring = self.app.telemetry
        frame = self._frame
        slots = self._slots
        sent = 0
        while sent < max_frames:
            k = 0
            while k < _BATCH and ring.read_into(slots[k]):
                k += 1
            if k == 0:
                break
            frame[0] = P.SYNC_WORD | (P.T_TELEMETRY << 16) | (k << 24)
            frame[1] = 4 + k * _RW * 4
            frame[2] = self.telemetry_seq
            frame[3] = ring.dropped
            crc = binascii.crc32(self._crc_spans[k])
            frame[4 + k * _RW] = crc - 0x100000000 if crc > 0x7FFFFFFF else crc
            self.write(self._frames[k])
            self.telemetry_seq = (self.telemetry_seq + 1) & P.SEQ_MASK
            sent += 1
            if k < _BATCH:
                break
        return sent
