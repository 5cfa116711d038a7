"""The virtual board's output as a board's USB serial sends it (host/link/board_line_endings.py): text
lines end in \\r\\n, our frames pass byte for byte, however the stream is cut into chunks."""

import json

from firmware import protocol as P
from host.link.board_line_endings import BoardLineEndings
from host.link.frames import FrameDecoder


def cooked(chunks):
    out = BoardLineEndings()
    return b"".join(out.feed(c) for c in chunks) + out.flush()


def frames():
    """A reply, a hello and a telemetry-like frame whose payloads are full of \\n and sync bytes."""
    records = bytes(range(256)) * 3
    return [
        P.encode_frame(P.T_OK, 7, json.dumps({"text": "a\nb", "x": [10, 13, 165, 90]}).encode()),
        P.encode_frame(P.T_HELLO, 0, b'{"version": "1"}'),
        P.encode_frame(P.T_TELEMETRY, 9, b"\n\n\n\n" + records[: 16 * 48], count=16),
    ]


def test_text_gets_crlf_and_existing_crlf_stays():
    assert cooked([b"a\nb\r\n>>> "]) == b"a\r\nb\r\n>>> "
    assert cooked([b"a\r", b"\nb\n"]) == b"a\r\nb\r\n"  # a \r\n cut between two chunks stays one
    assert cooked([b"\n\n"]) == b"\r\n\r\n"


def test_frames_pass_untouched_between_text_in_any_chunking():
    f = frames()
    stream = b"Traceback\n" + f[0] + b"KeyboardInterrupt: \n" + f[1] + f[2] + b"\xa5 not a frame\n>>> "
    want = b"Traceback\r\n" + f[0] + b"KeyboardInterrupt: \r\n" + f[1] + f[2] + b"\xa5 not a frame\r\n>>> "
    for size in (1, 2, 5, 11, 12, 13, 64, 777, len(stream)):
        chunks = [stream[i : i + size] for i in range(0, len(stream), size)]
        assert cooked(chunks) == want, size
    decoder = FrameDecoder()
    assert [fr.seq for fr in decoder.feed(want)] == [7, 0, 9] and decoder.crc_errors == 0


def test_a_frame_start_that_never_completes_is_text_after_a_flush():
    out = BoardLineEndings()
    assert out.feed(b"abc\xa5Z\x01") == b"abc"  # could be a frame's header: held
    assert out.flush() == b"\xa5Z\x01"
    assert out.feed(b"\n") == b"\r\n"
