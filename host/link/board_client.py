"""Talk to the lsea-kit firmware over a serial port (pyserial): handshake, commands, telemetry.

`BoardClient(port)` opens the port (a one-line UserError when it is missing, busy, not running
our firmware, running another version, or lacks a needed calibration), checks `status`, and then
`request(cmd, *args)` checks the command against firmware.protocol.COMMANDS (its name and each
argument's kind, as the board will), sends one command line and waits for its reply frame,
resending the same line on timeout (the firmware answers a repeated line with its cached reply,
so a retry never runs a command twice). Telemetry frames that arrive meanwhile are queued for `frames()`.
Which port to open (a device, `auto`, `sim`) is host/link/connect.py's business.

Slow is not silent: on a busy computer a virtual board (or the host itself) can be starved for
a second or two, so a request keeps resending for PATIENCE_S before it gives up, and the error
then says whether anything at all came from the board meanwhile ("the board stopped answering")
or it kept sending other data (overloaded, not dead).
"""

import collections
import random
import time

import serial

from firmware import protocol as P
from host.errors import LinkError, UserError
from host.link.frames import FrameDecoder
from host.link.port_advice import open_failure

HEARTBEAT_S = 0.25  # well inside the firmware's default 1000 ms host timeout
PATIENCE_S = 8.0  # wall-clock seconds a request resends before the board counts as not answering
RESET_RETRY_S = 3.0  # soft_reset sends its Ctrl-C/B/D sequence again after this long without a hello
# A board whose firmware has said it is booting (protocol.BOOTING, printed by board_main before
# the calibration's checks and tables: about a second on an RP2040, docs/emulated-pico.md, several
# on a slow emulator) is waited for this long and never interrupted, as a Ctrl-C meant to restart
# a silent board would cut the boot short. CircuitPython also compiles the firmware's source at
# boot: 4.3 s of an emulated Pico's time, 56-60 s and more of a computer running other emulators
# (a CI run gave up on it at 60 s, 2026-11-29). A boot that fails ends the wait at once (the
# REPL's prompt or CircuitPython's "press any key"), so the length only costs a silent hang.
BOOT_WAIT_S = 180.0
# A board that has said "soft reboot" after our Ctrl-D is restarting: its main.py is waited for
# this long, not reset again, before soft_reset gives up. Its first line can take seconds: an
# emulated Pico on a computer running three test workers and more took longer than 1.5 s (CI,
# 2026-11-27), and the Ctrl-C of a second reset then cut that boot short as well.
REBOOT_WAIT_S = 10.0
_SOFT_REBOOT = b"soft reboot"
_ANY_KEY = b"Press any key to enter the REPL"  # CircuitPython, after code.py ended
# CircuitPython's line as it starts code.py, before a line of ours: it compiles the firmware's
# source first, which an emulated Pico on a busy computer can take longer over than RESET_RETRY_S
_CODE_PY = b"code.py output:"
_BOOTING = P.BOOTING.encode()
_PROMPT = b">>> "
_RAW_REPL = b"raw REPL; CTRL-B to exit"
_TEXT_KEPT = 65536  # what soft_reset keeps of the board's output while it waits


class BoardError(UserError):
    """The firmware refused or failed a command; the message is the firmware's reason."""


class BoardClient:
    def __init__(self, port, timeout=0.5, retries=None, check=True, require_calibration=False, patience=PATIENCE_S):
        self.port = port
        self.timeout = timeout
        self.retries = retries  # None: resend every `timeout` until `patience` seconds have passed
        self.patience = patience
        self.received = 0  # bytes read from the board so far
        self.decoder = FrameDecoder()
        self.telemetry = collections.deque()
        self.hellos = 0
        self._text = None  # while soft_reset waits: every byte the board sent since its Ctrl-D
        self._seq = random.randrange(1, P.SEQ_MASK)  # a new session never repeats the last line
        self._last_heartbeat = 0.0
        self.serial = self._open(port)
        self.status_info = None
        if check:
            self.handshake(require_calibration=require_calibration)

    @staticmethod
    def _open(port):
        try:
            ser = serial.Serial(port, 115200, timeout=0.02, write_timeout=2, exclusive=True)
        except (serial.SerialException, OSError) as exc:
            raise UserError(open_failure(port, str(exc))) from None  # what to do, in this platform's words
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
    def handshake(self, require_calibration=False):
        try:
            status = self.request("status", retries=1)
        except TimeoutError:
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
        if status.get("interface") != P.interface_hash():
            raise UserError("board's interface table %s is not this host's %s (firmware from another version of lsea-kit): "
                            "reflash (host flash --port %s)" % (status.get("interface"), P.interface_hash(), self.port))
        want = P.VERSION
        if status.get("version") != want:
            raise UserError("board runs firmware %s, this host expects %s: reflash (host flash --port %s)" % (status.get("version"), want, self.port))
        if require_calibration and status.get("calibration_crc") is None:
            raise UserError("board has no usable calibration (%s): run the calibration, then host flash --calibration FILE" % status.get("calibration_error"))
        self.status_info = status
        return status

    def soft_reset(self, wait=1.5):
        """Leave whatever runs (Ctrl-C), go to the friendly REPL (Ctrl-B), soft reset (Ctrl-D):
        a board then boots main.py, i.e. the firmware. True once its hello frame came.

        What the board says after the Ctrl-D decides the wait. Our firmware saying it is booting
        (protocol.BOOTING), or CircuitPython saying it starts code.py: its hello is waited for up
        to BOOT_WAIT_S, the boot never interrupted.
        The REPL's prompt: nothing of ours runs (a board with MicroPython only, or main.py ended):
        False at once. "soft reboot" and nothing more yet (not the raw REPL's banner): the
        board restarts, and its main.py is given REBOOT_WAIT_S (at least `wait`) to say one of
        the above, never reset again (False after that: another main.py, a silent one).
        Anything else (silence, the raw REPL's banner): the sequence is sent again every
        RESET_RETRY_S while `wait` lasts; a tool killed halfway through a transfer (mpremote in
        raw-paste mode) can leave the REPL where the first sequence only ends the transfer, and
        the second one then resets."""
        ser = self.serial
        deadline = time.monotonic() + wait
        try:
            while True:
                ser.write(b"\r\x03\x03")
                time.sleep(0.2)
                ser.write(b"\r\x02")
                time.sleep(0.2)
                self._text = None
                self._read_frames()  # what came before the reset is not its answer
                self._text = b""
                ser.write(b"\x04")
                retry = min(deadline, time.monotonic() + RESET_RETRY_S)
                booting_until = rebooting_until = None
                while time.monotonic() < (booting_until or rebooting_until or retry):
                    for frame in self._read_frames():
                        if frame.type == P.T_HELLO:
                            return True
                    rebooted = _SOFT_REBOOT in self._text
                    after = self._text[self._text.rfind(_SOFT_REBOOT) + 1:] if rebooted else b""
                    if booting_until is None and (_BOOTING in after or _CODE_PY in after):
                        booting_until = time.monotonic() + BOOT_WAIT_S
                    if _RAW_REPL in after:
                        rebooting_until = None  # a soft reboot inside the raw REPL: no main.py follows
                    elif rebooted and rebooting_until is None:
                        rebooting_until = max(deadline, time.monotonic() + REBOOT_WAIT_S)
                    if _PROMPT in after or _ANY_KEY in after:
                        return False  # booted to the REPL: no main.py of ours (a new board), or it ended
                if booting_until is not None or rebooting_until is not None or time.monotonic() >= deadline:
                    return False
        finally:
            self._text = None

    def to_repl(self, wait=5.0):
        """Stop whatever runs (Ctrl-C) and leave the board at its REPL's prompt, where mpremote
        takes over. CircuitPython, once its code.py has ended, waits with "Press any key to enter
        the REPL" and drops what came before that line; the key is sent once it says so. True
        when the prompt came within `wait` s."""
        ser = self.serial
        self._text = b""
        try:
            ser.write(b"\r\x03\x03")
            deadline = time.monotonic() + wait
            keyed = False
            while time.monotonic() < deadline:
                self._read_frames()
                if not keyed and _ANY_KEY in self._text:
                    ser.write(b"\r")
                    keyed = True
                    self._text = b""
                if self._text.endswith(_PROMPT):
                    return True
            return False
        finally:
            self._text = None

    # -- requests ----------------------------------------------------------------------
    def _next_seq(self):
        self._seq = (self._seq + 1) % P.SEQ_MASK  # 0xFFFF is kept for unattributed errors
        return self._seq

    def _send(self, data):
        try:
            self.serial.write(data)
        except OSError as exc:  # serial.SerialException is one: the port vanished
            raise LinkError("lost the board on %s: %s (unplugged?)" % (self.port, str(exc).strip() or type(exc).__name__)) from None

    def _read_frames(self):
        try:
            data = self.serial.read(max(1, self.serial.in_waiting))
        except OSError as exc:  # serial.SerialException is one: the port vanished
            raise LinkError("lost the board on %s: %s (unplugged?)" % (self.port, str(exc).strip() or type(exc).__name__)) from None
        self.received += len(data)
        if data and self._text is not None:
            self._text = (self._text + data)[-_TEXT_KEPT:]
        frames = self.decoder.feed(data) if data else []
        for frame in frames:
            if frame.type == P.T_TELEMETRY:
                self.telemetry.append(frame)
            elif frame.type == P.T_HELLO:
                self.hellos += 1
        return frames

    def request(self, name, *args, timeout=None, retries=None):
        """Send one command; return the result of its ok frame, raise BoardError on an error
        frame and LinkError (a TimeoutError) when no reply came: after `retries` resends when given, else
        after resending every `timeout` for the client's patience (see the module docstring).
        The command and its arguments are checked against the board's interface
        (firmware.protocol.COMMANDS) first: ValueError for one the board would refuse, before
        anything is sent."""
        P.arguments(name, args)
        seq = self._next_seq()
        line = P.format_command(seq, name, *args)
        timeout = self.timeout if timeout is None else timeout
        retries = self.retries if retries is None else retries
        start, heard = time.monotonic(), self.received
        skipped, bad_crc = self.decoder.skipped_bytes, self.decoder.crc_errors
        tries = 0
        while retries is not None and tries <= retries or retries is None and (
                tries == 0 or time.monotonic() - start < self.patience):
            tries += 1
            self._send(line)
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
            raise LinkError("the board stopped answering: no reply to %s from %s in %.0f s, and nothing else came "
                               "from it" % (name, self.port, waited))
        came = self.received - heard
        junk = self.decoder.skipped_bytes - skipped
        if junk * 2 > came:  # mostly not our frames: a slow board still sends frames
            raise LinkError("no reply to %s from %s in %.0f s; what came (%d bytes) was mostly not lsea-kit frames "
                               "(%d bytes skipped, %d frames with a bad CRC): another program on the port, a wrong "
                               "port, or a bad cable?" % (name, self.port, waited, came, junk,
                                                          self.decoder.crc_errors - bad_crc))
        raise LinkError("no reply to %s from %s in %.0f s, though it kept sending (%d bytes): the board or this "
                           "computer is overloaded" % (name, self.port, waited, came))

    def call(self, name, *args, **kw):
        """request(): its LinkError is a UserError too, for the CLI's one line."""
        return self.request(name, *args, **kw)

    def clear_faults(self):
        """Clear the board's latched faults; returns (the faults cleared, the last fault's text),
        ([], None) when none were latched."""
        status = self.call("status")
        faults = status.get("faults") or []
        if faults:
            self.call("reset")
            self.call("status")  # the reset runs after its reply: this reply comes after it
        return faults, status.get("last_fault") if faults else None

    def heartbeat_if_due(self):
        if time.monotonic() - self._last_heartbeat >= HEARTBEAT_S:
            self._last_heartbeat = time.monotonic()
            # Fire and forget: the reply is skipped by frames(); a lost one is harmless.
            self._send(P.format_command(self._next_seq(), "heartbeat"))

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
