"""Talk to the lsea-kit firmware over a serial port (pyserial): handshake, commands, telemetry.

`BoardClient(port)` opens the port (a one-line UserError when it is missing, busy, not running
our firmware, running another version, or lacks a needed calibration), checks `status`, and then
`request(cmd, *args)` sends one command line and waits for its reply frame, resending the same
line on timeout (the firmware answers a repeated line with its cached reply, so a retry never
runs a command twice). Telemetry frames that arrive meanwhile are queued for `frames()`.
`open_board(port)` also accepts `sim`: a virtual board started for the life of the client.

Slow is not silent: on a busy computer a virtual board (or the host itself) can be starved for
a second or two, so a request keeps resending for PATIENCE_S before it gives up, and the error
then says whether anything at all came from the board meanwhile ("the board stopped answering")
or it kept sending other data (overloaded, not dead).
"""

import collections
import random
import time

import numpy as np
import serial

from firmware import protocol as P
from host.errors import UserError
from host.frames import FrameDecoder

HEARTBEAT_S = 0.25  # well inside the firmware's default 1000 ms host timeout
NO_DATA_S = 3.0  # wall-clock seconds without a telemetry record: the board stopped streaming
PATIENCE_S = 8.0  # wall-clock seconds a request resends before the board counts as not answering
_T_COL = P.FIELDS.index("t_us")
_T_WRAP = 1 << 30  # the firmware's t_us wraps here
_T_JUMP_US = 10000000  # a step this long is a restart of the firmware's clock, not time


class BoardTime:
    """The board's own time, in seconds, spanned by the telemetry records fed to it (their t_us).

    Host waits for the actuator (settling, holding, logging N seconds) are measured in it rather
    than in the host's wall clock: a virtual board on a loaded machine drops the ticks it cannot
    catch up (boards/sim/machine.py), so per wall-clock second it moves less, and a wait timed by
    the host's clock would give it less time than on a quiet machine. On a real board the two
    clocks agree."""

    def __init__(self):
        self.seconds = 0.0
        self._last = None

    def add(self, rows):
        """Count the records `rows` (int array, columns P.FIELDS); returns the seconds so far."""
        self.stamps(rows)
        return self.seconds

    def stamps(self, rows):
        """Count the records `rows` as add() does; returns each one's board time, in seconds."""
        if not len(rows):
            return np.zeros(0)
        t = rows[:, _T_COL].astype(np.int64)
        steps = np.diff(t, prepend=t[0] if self._last is None else self._last) % _T_WRAP
        steps[steps >= _T_JUMP_US] = 0
        times = self.seconds + np.cumsum(steps) / 1e6
        self.seconds = float(times[-1])
        self._last = int(t[-1])
        return times


class BoardError(UserError):
    """The firmware refused or failed a command; the message is the firmware's reason."""


def expected_firmware_version():
    from firmware.app import VERSION

    return VERSION


class BoardClient:
    def __init__(self, port, timeout=0.5, retries=None, check=True, require_calibration=False, start_firmware=True,
                 patience=PATIENCE_S):
        self.port = port
        self.timeout = timeout
        self.retries = retries  # None: resend every `timeout` until `patience` seconds have passed
        self.patience = patience
        self.received = 0  # bytes read from the board so far
        self.decoder = FrameDecoder()
        self.telemetry = collections.deque()
        self.hellos = 0
        self._seq = random.randrange(1, P.SEQ_MASK)  # a new session never repeats the last line
        self._last_heartbeat = 0.0
        self.serial = self._open(port)
        self.status_info = None
        if check:
            self.handshake(require_calibration=require_calibration, start_firmware=start_firmware)

    @staticmethod
    def _open(port):
        try:
            ser = serial.Serial(port, 115200, timeout=0.02, write_timeout=2, exclusive=True)
        except (serial.SerialException, OSError) as exc:
            text = str(exc)
            if "No such file" in text or "could not open port" in text and "No such" in text:
                raise UserError("serial port %s not found (is the board plugged in? try `host sim`)" % port)
            if "busy" in text.lower() or "lock" in text.lower():
                raise UserError("serial port %s is busy (close mpremote/minicom/another host command)" % port)
            raise UserError("cannot open serial port %s: %s" % (port, text))
        ser.reset_input_buffer()
        return ser

    def close(self):
        if self.serial is not None:
            self.serial.close()
            self.serial = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    # -- handshake ---------------------------------------------------------------------
    def handshake(self, require_calibration=False, start_firmware=True):
        try:
            status = self.request("status", retries=1)
        except TimeoutError:
            if not start_firmware:
                raise UserError("no lsea-kit firmware answers on %s (flash it: host flash --port %s)" % (self.port, self.port))
            # Maybe it sits at the REPL (after mpremote): soft-reset so main.py starts it.
            self.soft_reset()
            try:
                status = self.request("status", retries=2)
            except TimeoutError:
                raise UserError(
                    "no lsea-kit firmware answers on %s (not our firmware? flash it: host flash --port %s)"
                    % (self.port, self.port)
                )
        if status.get("protocol") != P.PROTOCOL_VERSION:
            raise UserError("board speaks protocol %s, this host %s: reflash (host flash)" % (status.get("protocol"), P.PROTOCOL_VERSION))
        want = expected_firmware_version()
        if status.get("version") != want:
            raise UserError("board runs firmware %s, this host expects %s: reflash (host flash --port %s)" % (status.get("version"), want, self.port))
        if require_calibration and status.get("calibration_crc") is None:
            raise UserError("board has no usable calibration (%s): run the calibration, then host flash --calibration FILE" % status.get("calibration_error"))
        self.status_info = status
        return status

    def soft_reset(self, wait=1.5):
        """Leave whatever runs (Ctrl-C), go to the friendly REPL (Ctrl-B), soft reset (Ctrl-D):
        a board then boots main.py, i.e. the firmware."""
        ser = self.serial
        ser.write(b"\r\x03\x03")
        time.sleep(0.2)
        ser.write(b"\r\x02")
        time.sleep(0.2)
        ser.write(b"\x04")
        deadline = time.monotonic() + wait
        while time.monotonic() < deadline:
            for frame in self._read_frames():
                if frame.type == P.T_HELLO:
                    return True
        return False

    # -- requests ----------------------------------------------------------------------
    def _next_seq(self):
        self._seq = (self._seq + 1) % P.SEQ_MASK  # 0xFFFF is kept for unattributed errors
        return self._seq

    def _read_frames(self):
        data = self.serial.read(max(1, self.serial.in_waiting))
        self.received += len(data)
        frames = self.decoder.feed(data) if data else []
        for frame in frames:
            if frame.type == P.T_TELEMETRY:
                self.telemetry.append(frame)
            elif frame.type == P.T_HELLO:
                self.hellos += 1
        return frames

    def request(self, name, *args, timeout=None, retries=None):
        """Send one command; return the result of its ok frame, raise BoardError on an error
        frame and TimeoutError when no reply came: after `retries` resends when given, else
        after resending every `timeout` for the client's patience (see the module docstring)."""
        seq = self._next_seq()
        line = P.format_command(seq, name, *args)
        timeout = self.timeout if timeout is None else timeout
        retries = self.retries if retries is None else retries
        start, heard = time.monotonic(), self.received
        tries = 0
        while retries is not None and tries <= retries or retries is None and (
                tries == 0 or time.monotonic() - start < self.patience):
            tries += 1
            self.serial.write(line)
            deadline = time.monotonic() + timeout
            while time.monotonic() < deadline:
                for frame in self._read_frames():
                    if frame.seq != seq or frame.type not in (P.T_OK, P.T_ERROR):
                        continue
                    if frame.type == P.T_ERROR:
                        raise BoardError("board refused %s: %s" % (name, frame.text()))
                    self._last_heartbeat = time.monotonic()
                    return frame.json()
        waited = time.monotonic() - start
        if self.received == heard:
            raise TimeoutError("the board stopped answering: no reply to %s from %s in %.0f s, and nothing else came "
                               "from it" % (name, self.port, waited))
        raise TimeoutError("no reply to %s from %s in %.0f s, though it kept sending (%d bytes): the board or this "
                           "computer is overloaded" % (name, self.port, waited, self.received - heard))

    def call(self, name, *args, **kw):
        """request() with a UserError instead of TimeoutError (for CLI commands)."""
        try:
            return self.request(name, *args, **kw)
        except TimeoutError as exc:
            raise UserError(str(exc))

    def heartbeat_if_due(self):
        if time.monotonic() - self._last_heartbeat >= HEARTBEAT_S:
            self._last_heartbeat = time.monotonic()
            # Fire and forget: the reply is skipped by frames(); a lost one is harmless.
            self.serial.write(P.format_command(self._next_seq(), "heartbeat"))

    # -- telemetry ---------------------------------------------------------------------
    def frames(self, timeout=0.1):
        """Telemetry frames received so far (waits up to `timeout` for at least one)."""
        deadline = time.monotonic() + timeout
        while not self.telemetry and time.monotonic() < deadline:
            self._read_frames()
        out = list(self.telemetry)
        self.telemetry.clear()
        return out

    def start_stream(self, hz):
        self.telemetry.clear()
        return self.call("stream", "on", int(hz))

    def stop_stream(self):
        result = self.call("stream", "off")
        time.sleep(0.05)
        self._read_frames()
        self.telemetry.clear()
        return result


class open_board:
    """Context manager: a BoardClient on `port`; `port == "sim"` starts a virtual board first,
    with `load` (a host.virtual_board.parse_load dict) hooked on its block."""

    def __init__(self, port, board=None, calibration=None, load=None, **client_options):
        from host.ports import resolve

        self.port = resolve(port)
        self.board = board
        self.calibration = calibration
        self.load = load
        self.options = client_options
        self.virtual = None
        self.client = None

    def __enter__(self):
        port = self.port
        if port == "sim":
            from host.virtual_board import DEFAULT_BOARD, VirtualBoard

            self.virtual = VirtualBoard(board=self.board or DEFAULT_BOARD, calibration=self.calibration, load=self.load)
            port = self.virtual.start()
        elif self.load is not None:
            raise UserError("--load only applies to --port sim (on a bench, hook the load by hand; "
                            "for a running host sim, start it with --load)")
        try:
            self.client = BoardClient(port, **self.options)
        except BaseException:
            self._cleanup()
            raise
        return self.client

    def _cleanup(self):
        if self.client is not None:
            self.client.close()
        if self.virtual is not None:
            self.virtual.stop()

    def __exit__(self, *exc):
        self._cleanup()


def add_port_arguments(parser):
    """--port (and --board/--calibration/--load for `--port sim`) shared by the board commands."""
    from host.virtual_board import LOAD_HELP, LOAD_METAVAR, parse_load

    parser.add_argument("--port", default="auto",
                        help="serial port of the board (e.g. /dev/ttyACM0), 'sim' for a virtual board started for this "
                        "command, or 'auto' (the default: the one board `host ports` finds)")
    parser.add_argument("--board", default=None, help="board file for --port sim (default boards/sim.json)")
    parser.add_argument("--calibration", default=None, help="calibration.json for --port sim")
    parser.add_argument("--load", type=parse_load, default=None, metavar=LOAD_METAVAR,
                        help="for --port sim: " + LOAD_HELP)


def settle(board, mode, target, field, tolerance, timeout_s=10.0, hold_s=0.3, progress=None, window=10, last=None):
    """Run `mode` towards `target` until telemetry `field` stays within `tolerance` of it for
    `hold_s`; returns (settled, last value, seconds). Heartbeats keep the host timeout away.
    `last`, a dict, receives the newest record (field name -> int), e.g. to say where it ended.
    `timeout_s`, `hold_s` and the seconds returned are the board's own time (BoardTime); if no
    telemetry arrives for NO_DATA_S of wall-clock time it gives up (not settled).

    The value judged is the mean of the last `window` records (0.1 s at the 100 Hz stream): a
    single reading carries the pots' noise, which near a knee (where one code spans ~3x more
    travel) is as large as a tight tolerance, so a still actuator would rarely look settled."""
    index = P.FIELDS.index(field)
    board.call("mode", mode)
    board.call("target", int(target))
    board.start_stream(100)
    clock = BoardTime()
    last_data = time.monotonic()
    inside_since = None
    value = None
    recent = []
    next_progress = 0.0
    try:
        while clock.seconds < timeout_s:
            board.heartbeat_if_due()
            frames = board.frames(timeout=0.05)
            for frame in frames:
                rows = frame.records()
                clock.add(rows)
                recent.extend(int(v) for v in rows[:, index])
                if last is not None and len(rows):
                    last.update(zip(P.FIELDS, (int(v) for v in rows[-1])))
            if frames:
                last_data = time.monotonic()
            elif time.monotonic() - last_data >= NO_DATA_S:
                break
            if not recent:
                continue
            del recent[:-window]
            value = sum(recent) / len(recent)
            now = clock.seconds
            if len(recent) == window and abs(value - target) <= tolerance:
                inside_since = now if inside_since is None else inside_since
                if now - inside_since >= hold_s:
                    return True, value, now
            else:
                inside_since = None
            if progress and now >= next_progress:
                next_progress = now + 0.2  # a readable refresh, not one line per frame
                progress(value, now)
        return False, value, clock.seconds
    finally:
        board.stop_stream()
