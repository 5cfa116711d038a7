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

_HEADER = struct.Struct(P.HEADER_FORMAT)
_CRC = struct.Struct("<I")
_KNOWN_TYPES = frozenset(P.TYPE_NAMES)
_RECORD_BYTES = 4 * P.RECORD_WORDS


class Frame(NamedTuple):
    type: int
    seq: int
    count: int
    payload: bytes

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
        append = out.append
        pos = 0
        end = len(buf)
        find = buf.find
        unpack_header = _HEADER.unpack_from
        unpack_word = _CRC.unpack_from
        crc = zlib.crc32
        sync = P.SYNC
        tel = P.T_TELEMETRY
        batch = P.TELEMETRY_BATCH
        hb = _HEADER.size  # P.HEADER_BYTES
        skipped = 0
        last = self._last_tseq
        lost = tel_frames = records = 0
        dropped = self.board_dropped
        view = memoryview(buf)
        try:
            while True:
                i = find(sync, pos)
                if i < 0:
                    keep = end - 1 if end > pos and buf[end - 1] == P.SYNC[0] else end
                    skipped += keep - pos
                    pos = keep
                    break
                if i > pos:
                    skipped += i - pos
                    pos = i
                if end - i < hb:
                    break
                _, _, ftype, count, length, seq = unpack_header(buf, i)
                # Telemetry is the common case: check its header inline, others in a function.
                if ftype == tel:
                    ok = 1 <= count <= batch and length == 4 + count * _RECORD_BYTES and seq <= P.SEQ_MASK
                else:
                    ok = frame_valid_header(ftype, count, length, seq)
                if not ok:
                    skipped += 1
                    pos = i + 1
                    continue
                body = hb + ((length + 3) & ~3)
                if end - i < body + 4:
                    if not final:
                        break
                    skipped += 1
                    pos = i + 1
                    continue
                if crc(view[i : i + body]) != unpack_word(buf, i + body)[0]:
                    self.crc_errors += 1
                    skipped += 1
                    pos = i + 1
                    continue
                append(Frame(ftype, seq, count, bytes(view[i + hb : i + hb + length])))
                pos = i + body + 4
                if ftype == tel:
                    tel_frames += 1
                    records += count
                    dropped = unpack_word(buf, i + hb)[0]
                    if last is not None:
                        lost += (seq - last - 1) & P.SEQ_MASK
                    last = seq
                elif ftype == P.T_HELLO:
                    last = None  # the board restarted: its telemetry numbering starts over
        finally:
            view.release()
        del buf[:pos]
        self.frames += len(out)
        self.skipped_bytes += skipped
        self.telemetry_frames += tel_frames
        self.records += records
        self.lost_frames += lost
        self.board_dropped = dropped if dropped < 2**31 else dropped - 2**32
        self._last_tseq = last
        return out

    def flush(self):
        """The stream ended: return the frames still recoverable from what is buffered."""
        return self.feed(b"", final=True)

    def pending(self):
        return len(self._buf)
