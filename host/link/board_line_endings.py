"""What a board's USB serial port sends, made from what the MicroPython unix port writes.

On a board, MicroPython writes text (print, the REPL, tracebacks) "cooked", every `\\n` as
`\\r\\n`, and bytes written with `sys.stdout.buffer.write` as they are; our firmware's frames go
out that way. The unix port writes both to its stdout unchanged and leaves `\\n` -> `\\r\\n` to the
terminal, which cannot be asked to do it here: it would mangle the frames too. Tools that talk to
boards count on `\\r\\n` (rshell splits its replies on it; mpremote's REPL staircases without it),
so the virtual board's relay passes its output through `BoardLineEndings`: frames (a valid
header of firmware/protocol.py, then exactly the length it gives) go through untouched, and in
everything else a `\\n` not already preceded by `\\r` becomes `\\r\\n`.

Other binary output that is not one of our frames (e.g. `mpremote mount`'s file protocol) is
cooked as text: the virtual board cannot tell it from print output.
"""

import struct

from firmware import protocol as P
from host.link.frames import frame_valid_header

_HEADER = struct.Struct(P.HEADER_FORMAT)
_SYNC0 = P.SYNC[0]


class BoardLineEndings:
    """Feed the unix port's output in chunks; each call returns what a board would have sent.
    A chunk that ends inside a frame's header is held back until the rest arrives (`flush()`
    lets it go as text when nothing more comes)."""

    def __init__(self):
        self._frame_left = 0  # bytes of a frame still to pass untouched
        self._held = b""  # a possible frame start whose header is not complete yet
        self._last_cr = False  # the last text byte sent was \r (a \n next is already a line end)

    def feed(self, data):
        data = self._held + bytes(data)
        self._held = b""
        out = []
        pos, end = 0, len(data)
        while pos < end:
            if self._frame_left:
                take = min(self._frame_left, end - pos)
                out.append(data[pos : pos + take])
                pos += take
                self._frame_left -= take
                self._last_cr = False
                continue
            i = data.find(_SYNC0, pos)
            if i < 0:
                out.append(self._text(data[pos:]))
                break
            if i > pos:
                out.append(self._text(data[pos:i]))
            frame = self._frame_length(data, i)
            if frame is None:  # not enough bytes to tell: wait for the next chunk
                self._held = data[i:]
                break
            if frame:
                self._frame_left = frame
                pos = i
            else:
                out.append(self._text(data[i : i + 1]))
                pos = i + 1
        return b"".join(out)

    def flush(self):
        """Nothing more is coming for now: what was held back is text after all."""
        held, self._held = self._held, b""
        return self._text(held) if held else b""

    @staticmethod
    def _frame_length(data, i):
        """The length of the frame starting at data[i], 0 when none starts there, None when the
        bytes so far cannot tell."""
        if i + 1 < len(data) and data[i + 1] != P.SYNC[1]:
            return 0
        if len(data) - i < _HEADER.size:
            return None
        _, _, ftype, count, length, seq = _HEADER.unpack_from(data, i)
        if not frame_valid_header(ftype, count, length, seq):
            return 0
        return P.HEADER_BYTES + P.padded(length) + P.CRC_BYTES

    def _text(self, text):
        if not text:
            return b""
        head = b""
        if self._last_cr and text[:1] == b"\n":
            head, text = b"\n", text[1:]
        self._last_cr = (head + text).endswith(b"\r")
        return head + text.replace(b"\r\n", b"\n").replace(b"\n", b"\r\n")
