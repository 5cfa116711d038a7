"""firmware/link.py with the real App on the simulated board, under CPython and real MicroPython:
every line gets exactly one well-formed reply, garbage gets an error, telemetry drains without
allocating."""

import binascii
import json
import random

from hypothesis import given, settings
from hypothesis import strategies as st

from boards.sim.machine import for_board
from firmware import protocol as P
from firmware.app import App
from firmware.link import Link
from host.link.frames import FrameDecoder
from testkit.interpreters import REPO, run_micropython

BOARD = str(REPO / "boards" / "sim.json")
TOKENS = ["idle", "open_loop", "position", "force", "on", "off", "kp_pos", "slew", "0", "-1", "1000", "2500",
          "99999999999", "1e3", "abc", "", "host_timeout_ms", "\xff"]


def valid_looking_line(rng):
    """A line with a correct checksum and random command/arguments (reaches dispatch)."""
    name = rng.choice(list(P.COMMAND_NAMES) + ["bogus"])
    args = [rng.choice(TOKENS) for _ in range(rng.randint(0, 3))]
    text = "!%d %s" % (rng.randint(0, P.SEQ_MASK - 1), " ".join([name] + [a for a in args if a]))
    return ("%s *%08x" % (text, P.crc32(text.encode("latin-1")))).encode("latin-1")


def random_lines(seed, n):
    rng = random.Random(seed)
    lines = []
    for _ in range(n):
        kind = rng.random()
        if kind < 0.5:
            line = valid_looking_line(rng)
        elif kind < 0.8:
            line = bytes(rng.randrange(256) for _ in range(rng.randint(1, 80)))
        else:  # a valid line with one byte changed
            line = bytearray(valid_looking_line(rng))
            line[rng.randrange(len(line))] = rng.randrange(256)
            line = bytes(line)
        line = line.replace(b"\n", b" ").replace(b"\r", b" ").strip() or b"x"
        lines.append(line)
    return lines


def replies(output):
    dec = FrameDecoder()
    frames = dec.feed(output) + dec.flush()
    assert dec.crc_errors == 0 and dec.skipped_bytes == 0  # the firmware writes nothing but frames
    return [f for f in frames if f.type in (P.T_OK, P.T_ERROR)]


def check_one_reply_per_line(lines, frames):
    assert len(frames) == len(lines)
    for line, frame in zip(lines, frames):
        try:
            seq, name, args = P.parse_command(line)
        except P.ProtocolError as exc:
            assert frame.type == P.T_ERROR, (line, frame)
            assert frame.seq == exc.args[0] & P.SEQ_MASK
            continue
        assert frame.seq == seq
        if frame.type == P.T_OK:
            frame.json()  # a valid JSON result
        else:
            assert frame.text()


def make_link():
    out = bytearray()
    app = App(BOARD, None, machine=for_board(BOARD))
    return app, Link(app, stdin=False, write=out.extend), out


@settings(max_examples=150, deadline=None)
@given(st.lists(st.binary(min_size=1, max_size=120).filter(lambda b: b"\n" not in b and b"\r" not in b), max_size=6),
       st.integers(0, 2**31))
def test_cpython_parser_answers_every_line_once(raw_lines, seed):
    app, link, out = make_link()
    lines = raw_lines + random_lines(seed, 6)
    for line in lines:
        link.handle_line(line)
    check_one_reply_per_line(lines, replies(bytes(out)))
    # whatever the lines did, the board is in a state it can be in: a known mode, a duty within
    # range, and with the mode idle the bridge off; after a stop it is off in any case
    st = app.status()
    assert st["mode"] in ("idle", "open_loop", "position", "force") and abs(st["duty"]) <= 10000, st
    app.step(None)
    if app.status()["mode"] == "idle":
        assert app.motor.duty == 0 and app.ctrl.duty == 0
    link.handle_line(P.format_command(60000, "stop").strip())
    app.step(None)
    assert app.status()["mode"] == "idle" and app.motor.duty == 0


def test_micropython_parser_answers_every_line_once(tmp_path):
    lines = random_lines(7, 400) + [P.format_command(1, "status").strip(), P.format_command(2, "mode", "open_loop").strip(),
                                    P.format_command(3, "target", 2500).strip(), P.format_command(4, "stop").strip()]
    src = tmp_path / "lines.json"
    src.write_text(json.dumps([binascii.hexlify(x).decode() for x in lines]))
    proc = run_micropython(
        "import json, binascii\nfrom boards.sim.machine import for_board\nfrom firmware.app import App\nfrom firmware.link import Link\n"
        "out = bytearray()\napp = App(%r, None, machine=for_board(%r))\nlink = Link(app, stdin=False, write=out.extend)\n"
        "for h in json.load(open(%r)):\n    link.handle_line(binascii.unhexlify(h))\n"
        "print(binascii.hexlify(out).decode())\n" % (BOARD, BOARD, str(src))
    )
    frames = replies(binascii.unhexlify(proc.stdout.strip().splitlines()[-1]))
    check_one_reply_per_line(lines, frames)
    assert frames[-4].json()["board"] == "sim" and frames[-3].type == P.T_OK and frames[-1].type == P.T_OK


def test_line_assembly_handles_overflow_crlf_and_retries():
    app, link, out = make_link()
    status = P.format_command(10, "status")
    link.feed(b"x" * (P.MAX_LINE + 50) + b"\r\n" + status.replace(b"\n", b"\r\n") + status)
    frames = replies(bytes(out))
    assert [f.type for f in frames] == [P.T_ERROR, P.T_OK, P.T_OK]
    assert frames[0].text() == "line too long" and frames[0].seq == P.SEQ_MASK
    assert frames[1].payload == frames[2].payload  # the retry got the cached answer
    assert link.lines == 2  # the CR and LF of one line make one line


def test_commands_reach_the_app():
    app, link, out = make_link()
    for seq, (name, args) in enumerate([("mode", ["open_loop"]), ("target", ["1234"]), ("set", ["slew", "77"]),
                                        ("get", ["slew"]), ("stream", ["on", "250"]), ("params", []), ("mode", ["position"])]):
        link.feed(P.format_command(seq, name, *args))
    frames = replies(bytes(out))
    assert [f.type for f in frames[:6]] == [P.T_OK] * 6
    assert app.ctrl.target == 1234 and frames[3].json() == 77
    assert app.telemetry.every == 4 and frames[4].json() == {"hz": 250}
    assert ["slew", 77, 500, 0, 10000, "duty per step"] in frames[5].json()  # name, value, default, limits, unit
    assert frames[6].type == P.T_ERROR and "calibration" in frames[6].text()  # no calibration: refused, not crashed


TELEMETRY_UNDER_HEAP_LOCK = """
import micropython, binascii
from boards.sim.machine import for_board
from firmware.app import App
from firmware.link import Link
app = App(%r, None, machine=for_board(%r))
app.set_stream(1000)
app.start()
app.machine.run_ticks(40)
views = [None]
def sink(b):
    views[0] = b
link = Link(app, stdin=False, write=sink)
out = []
n = 0  # made before the lock: a new global would grow this script's globals dict under it
while True:
    micropython.heap_lock()
    try:
        n = link.send_telemetry(1)
    finally:
        micropython.heap_unlock()
    if not n:
        break
    out.append(binascii.hexlify(bytes(views[0])).decode())
app.shutdown()
print(' '.join(out))
"""


def test_micropython_telemetry_drain_allocates_nothing():
    proc = run_micropython(TELEMETRY_UNDER_HEAP_LOCK % (BOARD, BOARD))
    data = b"".join(binascii.unhexlify(h) for h in proc.stdout.split())
    dec = FrameDecoder()
    frames = dec.feed(data)
    assert [f.count for f in frames] == [16, 16, 8] and dec.lost_frames == 0
    t = [int(r[0]) for f in frames for r in f.records()]
    assert len(t) == 40 and all(b - a == 1000 for a, b in zip(t, t[1:]))


def test_idle_main_loop_polling_allocates_nothing(mpy):
    # ipoll on a real stdin with nothing to read: the link's per-iteration cost when idle.
    proc = mpy(
        "import micropython\nfrom firmware.link import Link\n"
        "class A:\n    telemetry = __import__('firmware.telemetry').telemetry.Ring(4)\n"
        "link = Link(A(), write=lambda b: None)\nlink.poll()\n"
        "i = 0\nmicropython.heap_lock()\nwhile i < 1000:\n    link.poll()\n    i += 1\n"
        "micropython.heap_unlock()\nprint('ok', i)\n"
    )
    assert proc.stdout.split() == ["ok", "1000"]


def test_a_resent_command_counts_as_hearing_the_host():
    """A host whose replies get lost resends the same line; the firmware answers from its cache
    and must count it as the host speaking, or the watchdog stops the motor mid-request."""
    app, link, out = make_link()
    link.handle_line(P.format_command(1, "set", "host_timeout_ms", 50).strip())
    link.handle_line(P.format_command(2, "mode", "open_loop").strip())
    target = P.format_command(3, "target", 2000).strip()
    link.handle_line(target)
    for _ in range(6):  # 6 x 30 steps, the same line resent each time: never 50 silent steps
        for _ in range(30):
            app.step(None)
        link.handle_line(target)
    st = app.status()
    assert st["faults"] == [] and st["mode"] == "open_loop", st


def test_reset_happens_before_the_next_line_is_handled():
    """`reset` then `mode open_loop` read in one poll: the reset must not undo the mode."""
    app, link, out = make_link()
    link.handle_line(P.format_command(1, "mode", "open_loop").strip())
    app.safety.trip(4)  # a latched fault to clear
    link.handle_line(P.format_command(2, "reset").strip())
    link.handle_line(P.format_command(3, "mode", "open_loop").strip())
    link.poll = None  # nothing else may run the reset later
    assert app.status()["mode"] == "open_loop" and app.status()["faults"] == []
