"""The frame format and command lines: encoder/decoder agreement, resync, and fuzzing."""

import random
import re
import struct
import zlib

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware import protocol as P
from host.link.frames import FrameDecoder


def telemetry_frame(seq, records, dropped=0):
    payload = struct.pack("<i", dropped) + struct.pack("<%di" % (len(records) * P.RECORD_WORDS), *[v for r in records for v in r])
    return P.encode_frame(P.T_TELEMETRY, seq, payload, count=len(records))


def some_frames(rng, n):
    out = []
    for i in range(n):
        kind = rng.choice([P.T_OK, P.T_ERROR, P.T_TELEMETRY, P.T_HELLO])
        if kind == P.T_TELEMETRY:
            k = rng.randint(1, P.TELEMETRY_BATCH)
            recs = [[rng.randint(-(2**30), 2**30) for _ in range(P.RECORD_WORDS)] for _ in range(k)]
            out.append(telemetry_frame(i, recs, rng.randint(0, 100)))
        else:
            out.append(P.encode_frame(kind, rng.randint(0, P.SEQ_MASK), bytes(rng.randrange(256) for _ in range(rng.randint(0, 40)))))
    return out


def decode_all(stream, chunk_sizes=None):
    dec = FrameDecoder()
    frames = []
    i = 0
    rng = random.Random(len(stream))
    while i < len(stream):
        n = rng.randint(1, 200) if chunk_sizes is None else chunk_sizes
        frames += dec.feed(stream[i : i + n])
        i += n
    frames += dec.flush()
    return dec, frames


def reencode(frame):
    return P.encode_frame(frame.type, frame.seq, frame.payload, count=frame.count)


def test_frame_layout_is_whole_words_with_crc_over_header_and_payload():
    frame = P.encode_frame(P.T_OK, 7, b"null")
    assert frame[:2] == P.SYNC and frame[2] == P.T_OK
    assert len(frame) % 4 == 0
    assert struct.unpack_from("<II", frame, 4) == (4, 7)
    assert struct.unpack_from("<I", frame, len(frame) - 4)[0] == zlib.crc32(frame[:-4])


def test_command_lines_round_trip_and_never_contain_ctrl_c_or_ctrl_d():
    for seq, name, args in [(1, "status", ()), (65534, "target", (-123456,)), (9, "set", ("kp_pos", 300, "temp")),
                            (3, "stream", ("on", 1000))]:
        line = P.format_command(seq, name, *args)
        assert 3 not in line and 4 not in line and line.endswith(b"\n")
        assert P.parse_command(line.rstrip(b"\n")) == (seq, name, list(args))
    assert P.parse_command(P.format_command(9, "set", "kp_pos", 300).rstrip(b"\n")) == (9, "set", ["kp_pos", 300, False])


def test_arguments_are_read_by_their_kind_in_the_table():
    assert P.arguments("stream", ["on"]) == ["on", 1000]  # a default fills in
    assert P.arguments("stream", ["off"]) == ["off", 1000]
    assert P.arguments("target", ["-42"]) == [-42] and P.arguments("set", ["slew", "7"]) == ["slew", 7, False]
    for name, words, why in [
        ("mode", ["sideways"], "mode: name must be one of idle, open_loop, position, force, not sideways"),
        ("get", ["kpos"], "get: param must be one of kp_pos, "),
        ("set", ["slew"], "set needs param value"),
        ("target", ["12.5"], "not an integer: 12.5"),
        ("target", [str(2**30 + 1)], "out of range: 1073741825"),
        ("stop", ["now"], "stop takes at most 0 arguments"),
        ("set", ["slew", "7", "forever"], "set: temp must be one of temp, not forever"),
        ("fly", [], "unknown command fly"),
    ]:
        with pytest.raises(ValueError, match="^" + re.escape(why)):
            P.arguments(name, words)
        if name != "fly":  # the board answers a line with the same reason
            line = P.format_command(3, name, *words).rstrip(b"\n")
            with pytest.raises(P.ProtocolError) as info:
                P.parse_command(line)
            assert info.value.args[0] == 3 and info.value.args[1].startswith(why)


def test_every_command_runs_an_app_method_and_every_mode_is_the_controllers():
    from firmware import controller
    from firmware.app import App

    assert all(callable(getattr(App, row[2], None)) for row in P.COMMANDS)
    assert [c[0] for c in P.COMMANDS if c[3]] == ["reset"]  # runs after its reply
    assert [P.MODES.index(n) for n in ("idle", "open_loop", "position", "force")] == [
        controller.IDLE, controller.OPEN_LOOP, controller.POSITION, controller.FORCE]
    # the step reads parameter i as controller.P_<NAME>: the table's order is those indices
    assert [getattr(controller, "P_" + n.upper().removesuffix("_UM")) for n in P.PARAM_NAMES] == list(range(len(P.PARAMS)))


def test_format_command_refuses_words_that_would_break_the_line_or_reach_the_repl():
    cases = [
        ("a\x03b", "Ctrl-C (0x03), which would break into the board's REPL"),
        ("\x04", "Ctrl-D (0x04), which would break into the board's REPL"),
        ("kp pos", "whitespace (0x20)"),
        ("on\n", "whitespace (0x0a)"),
        ("x\ty", "whitespace (0x09)"),
        ("\x00", "control character (0x00)"),
        ("\x1b[A", "control character (0x1b)"),
        ("\x7f", "control character (0x7f)"),
        ("caf\u00e9", "is not ASCII"),
        ("\u2003", "is not ASCII"),
        ("", "is empty"),
    ]
    for word, why in cases:
        with pytest.raises(ValueError, match="argument 1 of set .*" + re.escape(why)):
            P.format_command(1, "set", word, 5)
    with pytest.raises(ValueError, match="command name 'sta tus' contains whitespace"):
        P.format_command(1, "sta tus")
    with pytest.raises(ValueError, match="longer than the board's 200"):
        P.format_command(1, "set", "p" * 200, 1)
    assert P.format_command(1, "set", "p" * 170, 1)  # long but within MAX_LINE: sent


@settings(max_examples=500, deadline=None)
@given(
    st.integers(min_value=0, max_value=P.SEQ_MASK - 1),
    st.sampled_from(P.COMMAND_NAMES),
    st.lists(st.one_of(st.text(max_size=20), st.integers(min_value=-(2**40), max_value=2**40), st.floats()), max_size=3),
)
def test_every_formatted_line_is_printable_ascii_or_refused(seq, name, args):
    try:
        line = P.format_command(seq, name, *args)
    except ValueError:
        # refused: some word really holds a byte outside printable ASCII, or the line is too long
        words = [name] + [str(a) for a in args]
        assert any(not w or any(not 0x21 <= ord(c) <= 0x7E for c in w) for w in words) or \
            len("!%d %s" % (seq, " ".join(words))) + 10 > P.MAX_LINE
        return
    assert line.endswith(b"\n")
    body = line[:-1]
    assert all(0x20 <= b <= 0x7E for b in body)  # printable ASCII: no Ctrl-C, no Ctrl-D, no CR/LF
    assert 3 not in line and 4 not in line and len(body) <= P.MAX_LINE
    # ... and the board reads back exactly the words that were sent, as the table reads them
    words = [str(a) for a in args]
    try:
        values = P.arguments(name, words)
    except ValueError as exc:
        with pytest.raises(P.ProtocolError) as info:
            P.parse_command(body)
        assert info.value.args == (seq, str(exc))
    else:
        assert P.parse_command(body) == (seq, name, values)


def test_parse_rejects_a_single_flipped_character():
    line = P.format_command(5, "target", 20000).rstrip(b"\n")
    bad = line.replace(b"20000", b"20001")
    try:
        P.parse_command(bad)
    except P.ProtocolError as exc:
        assert exc.args == (5, "checksum mismatch")
    else:
        raise AssertionError("corrupted line accepted")


def test_decoder_finds_every_frame_between_repl_text_and_noise():
    rng = random.Random(1)
    frames = some_frames(rng, 200)
    stream = b""
    for f in frames:
        stream += bytes(rng.randrange(256) for _ in range(rng.randint(0, 30))) + b">>> \r\nMPY: soft reboot\r\n" * rng.randint(0, 1) + f
    dec, got = decode_all(stream)
    assert [reencode(g) for g in got] == frames
    assert dec.crc_errors >= 0 and dec.skipped_bytes > 0


def test_lost_telemetry_frames_are_counted_from_sequence_gaps_including_wrap():
    seqs = [65530, 65531, 65533, 65535, 0, 4, 5]
    stream = b"".join(telemetry_frame(s, [[s] * P.RECORD_WORDS]) for s in seqs)
    dec, got = decode_all(stream)
    assert len(got) == len(seqs)
    assert dec.lost_frames == 1 + 1 + 3  # 65532, 65534, 1..3
    assert dec.records == len(seqs)
    assert got[0].records()[0, 0] == 65530


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=2000))
def test_random_bytes_never_crash_and_never_yield_a_frame(data):
    dec, got = decode_all(data)
    # A random stream could hold a valid frame only with a matching CRC32: never in practice.
    assert got == []
    assert dec.pending() < P.HEADER_BYTES + P.MAX_PAYLOAD + 8


@settings(max_examples=300, deadline=None)
@given(st.integers(0, 2**32 - 1), st.lists(st.tuples(st.integers(0, 10**6), st.integers(0, 255)), min_size=1, max_size=8))
def test_mutated_streams_never_yield_a_corrupted_frame(seed, mutations):
    rng = random.Random(seed)
    frames = some_frames(rng, 6)
    stream = bytearray(b"".join(frames))
    touched = set()
    for pos, value in mutations:
        pos %= len(stream)
        if stream[pos] != value:
            stream[pos] = value
            touched.add(pos)
    dec, got = decode_all(bytes(stream))
    originals = set(frames)
    for g in got:
        assert reencode(g) in originals  # every accepted frame is one that was really sent
    # and every frame whose bytes were not touched is still found
    start = 0
    intact = []
    for f in frames:
        if not any(start <= t < start + len(f) for t in touched):
            intact.append(f)
        start += len(f)
    got_bytes = [reencode(g) for g in got]
    for f in intact:
        assert f in got_bytes


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=300))
def test_parse_command_only_raises_protocol_error(line):
    try:
        seq, name, args = P.parse_command(line)
    except P.ProtocolError as exc:
        seq, message = exc.args
        assert -1 <= seq <= P.SEQ_MASK and isinstance(message, str)
    else:
        assert name in P.COMMAND_NAMES


def test_the_frame_header_format_is_its_declared_size():
    import struct

    assert struct.calcsize(P.HEADER_FORMAT) == P.HEADER_BYTES
