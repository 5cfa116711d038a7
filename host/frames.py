"""Host side of the frame format of firmware/protocol.py: a resynchronising decoder and helpers.

`FrameDecoder.feed(data)` returns the complete, CRC-checked frames found so far. Anything that is
not a valid frame (REPL text, boot banners, line noise, a frame with a bad CRC) is skipped byte by
byte until the next sync marker, so a corrupted frame is never returned. Telemetry frames carry a
16-bit sequence number: gaps count lost frames; the board's own ring-overflow counter rides in
each telemetry payload.
"""

import json
import struct
import zlib
from typing import NamedTuple

import numpy as np

from firmware import protocol as P

_HEADER = struct.Struct("<BBBBII")
_CRC = struct.Struct("<I")
_KNOWN_TYPES = frozenset(P.TYPE_NAMES)
_RECORD_BYTES = 4 * P.RECORD_WORDS


class Frame(NamedTuple):
    type: int
    seq: int
    count: int
    payload: bytes

    @property
    def type_name(self):
        return P.TYPE_NAMES.get(self.type, str(self.type))

    def json(self):
        return json.loads(self.payload.decode()) if self.payload else None

    def text(self):
        return self.payload.decode("utf-8", "replace")

    def dropped(self):
        """The board's cumulative count of records its ring overwrote (telemetry frames)."""
        return struct.unpack_from("<i", self.payload, 0)[0]

    def records(self):
        """Telemetry records as an int32 array of shape (count, RECORD_WORDS)."""
        return np.frombuffer(self.payload, "<i4", offset=4).reshape(self.count, P.RECORD_WORDS)


def frame_valid_header(ftype, count, length, seq):
    if ftype not in _KNOWN_TYPES or length > P.MAX_PAYLOAD or seq > P.SEQ_MASK:
        return False
    if ftype == P.T_TELEMETRY:
        return 1 <= count <= P.TELEMETRY_BATCH and length == 4 + count * _RECORD_BYTES
    return count == 0


class FrameDecoder:
    """Incremental decoder; counts skipped bytes, CRC failures and lost telemetry frames."""

    def __init__(self):
        self._buf = bytearray()
        self.frames = 0
        self.crc_errors = 0
        self.skipped_bytes = 0
        self.lost_frames = 0
        self.telemetry_frames = 0
        self.records = 0
        self.board_dropped = 0
        self._last_tseq = None

    def feed(self, data, final=False):
        """Frames completed by `data`. With final=True (the stream has ended) a header whose
        frame can no longer complete is skipped, so frames behind a corrupted length are found."""
        buf = self._buf
        buf += data
        out = []
        pos = 0
        end = len(buf)
        find = buf.find
        unpack_header = _HEADER.unpack_from
        crc = zlib.crc32
        view = memoryview(buf)
        try:
            while True:
                i = find(P.SYNC, pos)
                if i < 0:
                    keep = end - 1 if end > pos and buf[end - 1] == 0xA5 else end
                    self.skipped_bytes += keep - pos
                    pos = keep
                    break
                if i > pos:
                    self.skipped_bytes += i - pos
                    pos = i
                if end - i < P.HEADER_BYTES:
                    break
                _, _, ftype, count, length, seq = unpack_header(buf, i)
                if not frame_valid_header(ftype, count, length, seq):
                    self.skipped_bytes += 1
                    pos = i + 1
                    continue
                body = P.HEADER_BYTES + ((length + 3) & ~3)
                total = body + P.CRC_BYTES
                if end - i < total:
                    if not final:
                        break
                    self.skipped_bytes += 1
                    pos = i + 1
                    continue
                if crc(view[i : i + body]) != _CRC.unpack_from(buf, i + body)[0]:
                    self.crc_errors += 1
                    self.skipped_bytes += 1
                    pos = i + 1
                    continue
                frame = Frame(ftype, seq, count, bytes(view[i + P.HEADER_BYTES : i + P.HEADER_BYTES + length]))
                pos = i + total
                self._count(frame)
                out.append(frame)
        finally:
            view.release()
        del buf[:pos]
        return out

    def _count(self, frame):
        self.frames += 1
        if frame.type == P.T_TELEMETRY:
            self.telemetry_frames += 1
            self.records += frame.count
            self.board_dropped = frame.dropped()
            if self._last_tseq is not None:
                self.lost_frames += (frame.seq - self._last_tseq - 1) & P.SEQ_MASK
            self._last_tseq = frame.seq
        elif frame.type == P.T_HELLO:
            self._last_tseq = None  # the board restarted: its telemetry numbering starts over

    def flush(self):
        """The stream ended: return the frames still recoverable from what is buffered."""
        return self.feed(b"", final=True)

    def restart_sequence(self):
        """Forget the last telemetry sequence number (after stream off/on)."""
        self._last_tseq = None

    def pending(self):
        return len(self._buf)


def encode_command(seq, name, *args):
    return P.format_command(seq, name, *args)
