"""The virtual board: the real MicroPython unix port running the real firmware behind a pty.

A client (pyserial, mpremote, `host ...`) opens `VirtualBoard.path` (a /dev/pts/N slave) exactly
as it would open /dev/ttyACM0. Behind it a relay thread holds the pty master and copies bytes to
and from a `micropython` process whose stdio is a second pty (its controlling terminal, so Ctrl-C
raises KeyboardInterrupt as on a board, and the raw REPL works). The board's flash is a directory
of its own (`root`), mounted as "/" inside MicroPython (VfsPosix), holding main.py, firmware/,
board.json and calibration.json.

A load on the output block (`load=`, e.g. `parse_load("gauge@45")`) is what a person hooks on a
bench: the board writes it to `rig.json` in its root (host/link/flash_rig.py), where boards/sim/bench_rig.py applies it to
the simulated world at boot and within ~100 ms of a change (`set_load`).

Where a board soft-resets, the unix port exits; the relay then prints "MPY: soft reboot" and starts
micropython again: into the raw REPL when the reset came from the raw REPL (as a board does, which
is what mpremote expects), else booting main.py. Output nobody reads is dropped, as a USB CDC port
with no host attached does, so the firmware never blocks on a missing client; input the process
has not read yet waits in the relay (up to INPUT_BUFFER bytes, then the client's writes wait, as
USB's flow control makes them), so the relay never blocks on either side. Text reaches the
client with a board's \r\n line endings, frames byte for byte (host/link/board_line_endings.py).
"""

import collections
import json
import os
import select
import shutil
import signal
import subprocess
import tempfile
import threading
import time
from pathlib import Path

try:  # POSIX only: a pseudo-terminal. Everything else in the host works without them.
    import fcntl
    import termios
    import tty
except ImportError:  # Windows
    fcntl = termios = tty = None

from firmware.protocol import SYNC
from host.link.board_line_endings import BoardLineEndings
from host.link.firmware_files import install_factory
from host.link.flash_rig import FlashRig
from host.errors import UserError, install_hint

REPO = Path(__file__).resolve().parents[2]
DEFAULT_BOARD = REPO / "boards" / "sim.json"
HEAP = "4M"
_RAW_BANNER = b"raw REPL; CTRL-B to exit"
_FRIENDLY_PROMPT = b">>> "

# A board keeps what the host sends while it boots; a Ctrl-C that reached micropython before it
# installed its SIGINT handler would kill it instead of interrupting main.py, and bytes that
# arrive before its REPL prompt are flushed. So the relay holds the client's bytes until the new
# process is ready (_ready_for_input), or for at most this long (a main.py that runs silently
# must still get its Ctrl-C).
BOOT_INPUT_HOLD_S = 1.0

INPUT_BUFFER = 1 << 16  # client bytes the relay holds for a process that is not reading (then it stops taking more)
EXITS_KEPT = 8  # the process exits a BoardSilent error can name (recent_exits)
RAW_BOOT_RETRIES = 3  # a raw-REPL boot that keeps dying before its prompt is given up (main.py boots)
RESET_EXIT = 77  # exit status of machine.reset() on the virtual board: boot main.py again

# Runs first in every micropython process: mount the board's flash as "/"; install as `machine`
# the simulated actuator's (boards/sim/machine.py, built from board.json) when the board file
# says it is simulated, else the unix port's; and give it a reset() (the unix port has none) that
# exits with RESET_EXIT so the relay reboots into main.py, as mpremote's `reset` expects of a board.
_BOOT = """\
import os, sys
os.mount(os.VfsPosix(%r), '/')
os.chdir('/')
sys.path[:] = ['', '.frozen', '/lib']
import machine as _hw_machine
try:
    import json
    with open('board.json') as _f:
        _simulated = json.load(_f).get('simulated')
except (OSError, ValueError):
    _simulated = False
if _simulated:
    from boards.sim.machine import for_board
    _hw_machine = for_board('board.json')
class _VirtualMachine:
    def __getattr__(self, name):
        return getattr(_hw_machine, name)
    def reset(self, _exit=sys.exit):
        _exit(%d)
sys.modules['machine'] = _VirtualMachine()
del _VirtualMachine
if %r and 'main.py' in os.listdir('/'):
    del os, sys
    exec(open('main.py').read(), {'__name__': '__main__'})
"""


def micropython_executable():
    import sys

    beside = Path(sys.executable).parent / "micropython"
    found = str(beside) if beside.exists() else shutil.which("micropython")
    if not found:
        raise UserError("micropython (the unix port, for the virtual board) not found: %s" % install_hint("sim"))
    return found


# The simulated actuator's calibration, made by the project's own guided calibration on
# boards/sim.json (`python boards/make_sim_calibration.py` makes it again; a test checks that it
# still matches the model): what `--port sim` and `host sim` start with, so that a newcomer can
# move the actuator within seconds instead of after a 5-minute `host calibrate`.
READY_CALIBRATION = REPO / "boards" / "sim" / "calibration.json"


def ready_calibration(board_path):
    """The shipped calibration for a virtual board of `board_path`: READY_CALIBRATION for
    boards/sim.json, None for any other board file (its actuator differs)."""
    if Path(board_path).resolve() == DEFAULT_BOARD.resolve() and READY_CALIBRATION.is_file():
        return READY_CALIBRATION
    return None


def _set_pty_mode(fd):
    """Raw bytes both ways (no CR/LF translation, no echo) but Ctrl-C still raises SIGINT, as
    on a board; Ctrl-\\ and Ctrl-Z are plain bytes there, so they must not quit or stop
    micropython here (the terminal's other signal characters are switched off)."""
    tty.setraw(fd)
    attrs = termios.tcgetattr(fd)
    attrs[3] |= termios.ISIG
    off = bytes([os.fpathconf(fd, "PC_VDISABLE") & 0xFF])
    for name in ("VQUIT", "VSUSP", "VDSUSP"):
        if hasattr(termios, name):
            attrs[6][getattr(termios, name)] = off
    termios.tcsetattr(fd, termios.TCSANOW, attrs)


class VirtualBoard:
    """A simulated board on a pseudo-terminal. Use as a context manager or start()/stop()."""

    chip = None  # the MicroPython unix port, not an emulated chip

    def __init__(self, board=DEFAULT_BOARD, calibration=None, root=None, factory=True, log=None, load=None):
        self.board_path = Path(board)
        if not self.board_path.is_file():
            raise UserError("board file not found: %s" % board)
        self.calibration = calibration
        self._own_root = root is None
        self.root = Path(root) if root else Path(tempfile.mkdtemp(prefix="lsea-vboard-"))
        self._rig = FlashRig(self.root)
        self.factory = factory
        self.log = log
        self.load = load  # None: leave the rig as it is (the board file's: no load)
        self.path = None
        self.boots = 0
        self.dropped_bytes = 0
        self._client_absent = False
        self._child = None
        self._inner = None
        self._master = self._slave = None
        self._stop = threading.Event()
        self._thread = None
        self._tail = b""
        self._raw_mode = False
        self._swallow = None  # while booting into the raw REPL: output held back until ">>> "
        self._raw_boot_pending = False  # a raw-REPL boot whose raw REPL has not come up yet
        self._raw_boot_failures = 0  # raw-REPL boots in a row that died before their raw REPL
        self._line_endings = BoardLineEndings()
        self._held_input = b""  # the client's bytes the process has not taken yet
        self._hold_input_until = None  # while a new process boots: monotonic time to give up waiting
        self._boot_started = 0.0  # monotonic time of the running process's start
        self._boot_kind = "main.py"  # what it booted into: "main.py" or "raw REPL"
        self._boot_ready = False  # it printed a prompt or the firmware's hello
        self.exits = collections.deque(maxlen=EXITS_KEPT)  # one line per process exit, and the relay's end

    # -- lifecycle ---------------------------------------------------------------------
    def start(self):
        if fcntl is None:
            raise UserError("the virtual board (--port sim, host sim) needs a pseudo-terminal: Linux or macOS, "
                            "or WSL on Windows; real boards work here with --port COMn")
        if self.factory:
            install_factory(self.root, self.board_path, self.calibration)
        if self.load is not None:
            self.set_load(self.load)  # in place before main.py boots: the world starts with it
        self._master, self._slave = os.openpty()
        _set_pty_mode(self._slave)
        fl = fcntl.fcntl(self._master, fcntl.F_GETFL)
        fcntl.fcntl(self._master, fcntl.F_SETFL, fl | os.O_NONBLOCK)
        self.path = os.ttyname(self._slave)
        self._spawn(run_main=True)
        self._thread = threading.Thread(target=self._relay, name="virtual-board", daemon=True)
        self._thread.start()
        _RUNNING[self.path] = self
        return self.path

    def stop(self):
        _RUNNING.pop(self.path, None)
        self._stop.set()
        if self._thread:
            self._thread.join(timeout=5)
        self._kill_child()
        for fd in (self._master, self._slave):
            if fd is not None:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self._master = self._slave = None
        if self._own_root:
            shutil.rmtree(self.root, ignore_errors=True)

    # -- the bench rig: what a person mounts and reads (host/link/flash_rig.py) --------------
    @property
    def actuator(self):
        """The simulated actuator's description (the board file's "actuator")."""
        return json.loads(self.board_path.read_text()).get("actuator") or {}

    def rig(self, rig, wait=True):
        """Mount what `rig` says (reference, load, fault); see FlashRig.mount."""
        return self._rig.mount(rig, wait)

    def set_load(self, load):
        """Hook a load on the block (a parse_load dict); the running firmware's rig applies it
        within ~100 ms."""
        self._rig.mount({"load": dict(load)}, wait=False)
        self.load = dict(load)

    def gauge(self, beat=None, timeout_s=10.0):
        """The force gauge's display, {"force_n", "t_s"}, rewritten after the call; see FlashRig.gauge."""
        return self._rig.gauge(beat, timeout_s)

    def __enter__(self):
        self.start()
        return self

    def __exit__(self, *exc):
        self.stop()

    def _spawn(self, run_main):
        inner, child_side = os.openpty()
        _set_pty_mode(child_side)

        def controlling_tty():
            os.setsid()
            fcntl.ioctl(0, termios.TIOCSCTTY, 0)

        args = [micropython_executable(), "-X", "heapsize=" + HEAP, "-i", "-c", _BOOT % (str(self.root), RESET_EXIT, run_main)]
        self._child = subprocess.Popen(
            args, stdin=child_side, stdout=child_side, stderr=child_side, cwd=str(self.root),
            preexec_fn=controlling_tty, close_fds=True,
        )
        os.close(child_side)
        os.set_blocking(inner, False)  # the relay never waits on the process (_to_child)
        self._inner = inner
        self._tail = b""
        self._raw_mode = False
        self._swallow = None if run_main else b""
        self._raw_boot_pending = not run_main
        self._line_endings = BoardLineEndings()  # a frame the last process left unfinished is over
        self._hold_input_until = time.monotonic() + BOOT_INPUT_HOLD_S
        self._boot_started = time.monotonic()
        self._boot_kind = "main.py" if run_main else "raw REPL"
        self._boot_ready = False
        self.boots += 1

    def _kill_child(self):
        child, self._child = self._child, None
        if child and child.poll() is None:
            child.send_signal(signal.SIGTERM)
            try:
                child.wait(timeout=3)
            except subprocess.TimeoutExpired:
                child.kill()
                child.wait()
        if self._inner is not None:
            try:
                os.close(self._inner)
            except OSError:
                pass
            self._inner = None

    # -- relay ---------------------------------------------------------------------------
    def _to_client(self, data, patience_s=0.1):
        """Write all of `data` to the client side; wait up to patience_s for a slow reader (the
        firmware then waits too, as on a USB port with a busy host), then drop the rest (nobody
        is reading: a USB port drops it too)."""
        view = memoryview(data)
        deadline = None
        patience_s = 0.0 if self._client_absent else patience_s
        while view:
            try:
                view = view[os.write(self._master, view) :]
                continue
            except BlockingIOError:
                pass
            except OSError:
                break
            now = time.monotonic()
            deadline = deadline or now + patience_s
            if now >= deadline:
                self._client_absent = True  # stop waiting until the client talks again
                break
            select.select([], [self._master], [], deadline - now)
        self.dropped_bytes += len(view)

    def _from_child(self, data):
        self._tail = (self._tail + data)[-64:]
        self._track_repl_mode()
        if self.log:
            self.log.write(data)
        if self._swallow is not None:
            # Booting after a raw-REPL soft reset: hide the banner, then enter the raw REPL
            # so the host sees what a board prints ("raw REPL; CTRL-B to exit\r\n>").
            self._swallow += data
            if _FRIENDLY_PROMPT in self._swallow:
                self._swallow = None
                try:
                    os.write(self._inner, b"\x01")
                except BlockingIOError:
                    self._held_input = b"\x01" + self._held_input  # its input is full: first when it reads
                except OSError:
                    pass  # it died meanwhile: the EOF that follows reboots it (raw again, see _reboot)
            return
        if self._raw_boot_pending and self._raw_mode:
            self._raw_boot_pending = False  # its raw REPL is up: what mpremote waits for
            self._raw_boot_failures = 0
        self._to_client(self._line_endings.feed(data))

    def _track_repl_mode(self):
        raw = self._tail.rfind(_RAW_BANNER)
        friendly = self._tail.rfind(_FRIENDLY_PROMPT)
        if raw > friendly:
            self._raw_mode = True
        elif friendly > raw:
            self._raw_mode = False

    def _relay(self):
        try:
            self._relay_loop()
        except BaseException as exc:  # the board falls silent: say why where its silence is reported
            self.exits.append("the relay stopped: %s: %s" % (type(exc).__name__, exc))
            self._kill_child()
            raise

    def _relay_loop(self):
        poller = select.poll()
        masks = {}  # fd -> the events it is registered for

        def want(fd, mask):
            if masks.get(fd) != mask:
                (poller.modify if fd in masks else poller.register)(fd, mask)
                masks[fd] = mask

        while not self._stop.is_set():
            for fd in [fd for fd in masks if fd not in (self._master, self._inner)]:
                try:
                    poller.unregister(fd)  # a process that exited: its pty is closed
                except (KeyError, ValueError):
                    pass
                del masks[fd]
            # Take the client's bytes only while few wait for the process (else its writes wait,
            # as USB's flow control makes them); wait for room in the process's input when some do.
            want(self._master, select.POLLIN if len(self._held_input) < INPUT_BUFFER else 0)
            feeding = self._held_input and self._hold_input_until is None
            want(self._inner, select.POLLIN | (select.POLLOUT if feeding else 0))
            events = poller.poll(100 if self._hold_input_until is None else 10)
            if self._held_input and self._hold_input_until is not None and time.monotonic() >= self._hold_input_until:
                self._hold_input_until = None
                self._to_child(b"")
            if not events:
                text = self._line_endings.flush()
                if text:
                    self._to_client(text)
            for fd, event in events:
                if fd == self._master and event & select.POLLIN:
                    try:
                        data = os.read(self._master, 4096)
                    except (BlockingIOError, OSError):
                        continue
                    self._client_absent = False
                    self._to_child(data)
                elif fd == self._inner and event & (select.POLLIN | select.POLLHUP | select.POLLERR):
                    try:
                        data = os.read(self._inner, 65536)
                    except BlockingIOError:
                        continue
                    except OSError:
                        data = b""
                    if data:
                        self._from_child(data)
                        if self._ready_for_input(data):
                            self._boot_ready = True
                            if self._hold_input_until is not None:
                                self._hold_input_until = None
                                self._to_child(b"")
                    else:
                        self._reboot()
                elif fd == self._inner and event & select.POLLOUT:
                    self._to_child(b"")

    def _ready_for_input(self, data):
        """The new process has booted: the firmware sent a frame (its hello), or a REPL prompt is
        out (the unix port flushes its terminal's input when it starts reading a REPL line, so
        bytes sent before the prompt would be lost, which a board never does)."""
        if self._swallow is not None:
            return False  # still booting into the raw REPL
        return SYNC in data or self._tail.endswith(_FRIENDLY_PROMPT) or self._tail.endswith(_RAW_BANNER + b"\r\n>")

    def _to_child(self, data):
        """Queue the client's `data` for the process and write what its input takes now (none
        while it boots); the rest waits for the relay's next POLLOUT. A blocking write here could
        hang for good: the process, not reading, may itself be blocked writing its output to
        this thread."""
        self._held_input += data
        if self._hold_input_until is not None or not self._held_input or self._inner is None:
            return
        try:
            taken = os.write(self._inner, self._held_input)
        except BlockingIOError:
            taken = 0
        except OSError:
            taken = len(self._held_input)  # it died: its EOF reboots it; a reset loses its input too
        self._held_input = self._held_input[taken:]

    def _reboot(self):
        """micropython exited (a soft reset): restart it as a board restarts."""
        code = None
        if self._child is not None:
            try:
                code = self._child.wait(timeout=2)
            except subprocess.TimeoutExpired:
                pass
        self.exits.append("boot %d (%s) exited with %s after %.1f s%s" % (
            self.boots, self._boot_kind,
            code, time.monotonic() - self._boot_started, "" if self._boot_ready else ", before its prompt"))
        if self._hold_input_until is None:
            # What it had not read yet dies with it, as a board's reset loses it: the next process
            # must not get the rest of a line from the middle. Input held while it still booted
            # (a Ctrl-C sent meanwhile) is the next process's.
            self._held_input = b""
        hard = code == RESET_EXIT
        raw = self._raw_mode and not hard
        if self._raw_boot_pending and not hard and self._raw_boot_failures < RAW_BOOT_RETRIES:
            # A boot into the raw REPL (after a soft reset there, which mpremote waits out for
            # the raw REPL's banner) died before its raw REPL came up: boot it the same way again.
            # Booting main.py instead would leave mpremote waiting for a banner that never comes
            # (it reads a pty without a timeout): the 120 s "no answer" of a reflash.
            self._raw_boot_failures += 1
            raw = True
        self._kill_child()
        if self._stop.is_set():
            return
        self._to_client(b"MPY: soft reboot\r\n")
        time.sleep(0.01)
        self._spawn(run_main=not raw)


_RUNNING = {}  # serial path -> the VirtualBoard started in this process on it


def recent_exits(path):
    """What the virtual board on serial `path` (started in this process) last saw end: its
    processes' exits and, if it stopped, the relay's; '' for any other port. For an error that
    says a board fell silent."""
    board = _RUNNING.get(path)
    return "; ".join(board.exits) if board is not None else ""
