"""An emulated Raspberry Pi Pico with the simulated actuator wired to its pins, on a pseudo-terminal.

`EmulatedPico(uf2=...)` starts the bench process (bench.py: the RP2040 of rp2040js running the
Pico firmware a user downloads, in lockstep with boards/sim's actuator) and gives the serial
device a client opens as it would /dev/ttyACM0: `host flash`, `mpremote`, pyserial. The Pico
starts as one does out of its box with MicroPython on it: an empty filesystem, unless
`flash_image` names a file that keeps it between runs (written through on every flash write).
Our firmware gets onto it the way it gets onto a real Pico, by `host flash` over its USB serial.

The bench rig reaches the actuator directly, through the bench process (`rig()`, `gauge()`,
`state()`), never through the board's filesystem.
"""

import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from host.errors import UserError

REPO = Path(__file__).resolve().parents[3]
PICO_BOARD = REPO / "boards" / "pico.json"
CIRCUITPYTHON_PICO_BOARD = REPO / "boards" / "pico_circuitpython.json"  # the same pins, for CircuitPython
SIM_BOARD = REPO / "boards" / "sim.json"  # whose "actuator" is wired to the Pico by default
UF2_ENV = "LSEA_PICO_UF2"
UF2_HELP = ("the Pico's firmware: MicroPython (RPI_PICO .uf2, from https://micropython.org/download/RPI_PICO/; "
            "1.26 or later for the hard timer) or CircuitPython (raspberry_pi_pico .uf2, from "
            "https://circuitpython.org/board/raspberry_pi_pico/, told apart by its contents); default $%s" % UF2_ENV)
# MicroPython's rp2 port on a 2 MiB Pico keeps its littlefs in the last 1408 KiB of flash
# (MICROPY_HW_FLASH_STORAGE_BYTES for RPI_PICO); the firmware lies below it.
FLASH_BYTES = 2 * 1024 * 1024
FS_SIZE = 1408 * 1024
FS_OFFSET = FLASH_BYTES - FS_SIZE
# CircuitPython's raspberrypi port keeps its CIRCUITPY FAT drive (512-byte blocks) in the second
# MiB of a 2 MiB flash, after 1020 KiB of firmware and the 4 KiB of microcontroller.nvm
# (CIRCUITPY_FIRMWARE_SIZE, CIRCUITPY_INTERNAL_NVM_*): the flash image keeps both, from the nvm on,
# so what the firmware keeps there (firmware/records.py) survives a restart as on a Pico
CIRCUITPY_NVM_BYTES = 4 * 1024
CIRCUITPY_FS_OFFSET = 1024 * 1024 - CIRCUITPY_NVM_BYTES
CIRCUITPY_FS_SIZE = 1024 * 1024 + CIRCUITPY_NVM_BYTES
START_TIMEOUT_S = 60


def resolve_uf2(uf2=None):
    """The UF2 to run: `uf2`, else $LSEA_PICO_UF2; UserError naming both when there is none."""
    path = uf2 or os.environ.get(UF2_ENV)
    if not path:
        raise UserError("the emulated Pico needs MicroPython's Pico firmware: give --uf2 FILE "
                        "(RPI_PICO .uf2 from https://micropython.org/download/RPI_PICO/) or set %s" % UF2_ENV)
    if not Path(path).is_file():
        raise UserError("firmware for the emulated Pico not found: %s" % path)
    with open(path, "rb") as f:
        head = f.read(8)
    if head[:4] != b"UF2\n":
        raise UserError("%s is not a UF2 file (it does not start with a UF2 block)" % path)
    return str(Path(path).resolve())


def uf2_runtime(path):
    """"circuitpython" when the UF2 holds CircuitPython (its banner's name is in the image), else
    "micropython": they lay out the flash differently, and CircuitPython needs the BOOTSEL pull-up."""
    with open(path, "rb") as f:
        data = f.read()
    return "circuitpython" if b"CircuitPython" in data else "micropython"


def default_board(uf2=None):
    """The board file for the Pico firmware `uf2` runs (resolve_uf2's): boards/pico.json for
    MicroPython, boards/pico_circuitpython.json for CircuitPython."""
    return CIRCUITPYTHON_PICO_BOARD if uf2_runtime(resolve_uf2(uf2)) == "circuitpython" else PICO_BOARD


def load_actuator(path=SIM_BOARD):
    """The simulated actuator (a board file's "actuator" section) and its seed."""
    try:
        data = json.loads(Path(path).read_text())
    except (OSError, ValueError) as exc:
        raise UserError("cannot read the simulated actuator from %s: %s" % (path, exc)) from None
    if "actuator" not in data:
        raise UserError("%s describes no simulated actuator (no \"actuator\" section)" % path)
    return data["actuator"], data.get("seed", 0)


class EmulatedPico:
    """A Pico on rp2040js with the simulated actuator on its pins. Context manager or start()/stop()."""

    chip = "rp2040"

    def __init__(self, uf2=None, board=None, actuator=SIM_BOARD, flash_image=None, load=None, log=None):
        self.uf2 = resolve_uf2(uf2)
        self.runtime = uf2_runtime(self.uf2)
        self.board_path = Path(board or default_board(self.uf2))
        try:
            self.board = json.loads(self.board_path.read_text())
        except (OSError, ValueError) as exc:
            raise UserError("cannot read board file %s: %s" % (board, exc)) from None
        self.actuator_path = Path(actuator)
        self.actuator, self.seed = load_actuator(actuator)
        self._own_image = flash_image is None
        self.flash_image = Path(flash_image) if flash_image else None
        self.load = load
        self.log = log
        self.path = None
        self._proc = None
        self._lock = threading.Lock()
        self._config_file = None

    @property
    def root(self):
        """No filesystem of the board's is on this computer (the rig talks to the bench)."""
        return None

    def start(self):
        from host.link.emulated_pico.node import ensure_installed

        if os.name != "posix":
            raise UserError("the emulated Pico needs a pseudo-terminal: Linux or macOS, or WSL on Windows")
        ensure_installed(progress=self.log)
        if self.flash_image is None:
            fd, name = tempfile.mkstemp(prefix="lsea-pico-flash-", suffix=".img")
            os.close(fd)
            os.unlink(name)  # an absent image is an erased chip
            self.flash_image = Path(name)
        circuitpython = self.runtime == "circuitpython"
        config = {"board": self.board, "actuator": self.actuator, "seed": self.seed, "uf2": self.uf2,
                  "fs_image": str(self.flash_image),
                  "fs_offset": CIRCUITPY_FS_OFFSET if circuitpython else FS_OFFSET,
                  "fs_size": CIRCUITPY_FS_SIZE if circuitpython else FS_SIZE,
                  "bootsel_pullup": circuitpython}
        if self.load is not None:
            config["rig"] = {"load": dict(self.load)}
        fd, self._config_file = tempfile.mkstemp(prefix="lsea-pico-", suffix=".json")
        with os.fdopen(fd, "w") as f:
            json.dump(config, f)
        self._proc = subprocess.Popen(
            [sys.executable, "-m", "host.link.emulated_pico.bench", self._config_file],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, cwd=str(REPO),
            start_new_session=True)  # a Ctrl-C meant for the host does not kill the board under it
        self._out = b""
        self._asked = 0
        first = self._read_line(START_TIMEOUT_S)
        try:
            self.path = json.loads(first)["path"]
        except (ValueError, KeyError, TypeError):
            self.stop()
            raise UserError("the emulated Pico did not start (%s)" % (first.strip() or "no answer")) from None
        return self.path

    def _read_line(self, timeout):
        """The bench's next line of output ("" when none came within `timeout` s)."""
        import select

        fd = self._proc.stdout.fileno()
        deadline = time.monotonic() + timeout
        while b"\n" not in self._out:
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([fd], [], [], left)[0]:
                return ""
            chunk = os.read(fd, 65536)
            if not chunk:
                return ""
            self._out += chunk
        line, self._out = self._out.split(b"\n", 1)
        return line.decode()

    def ask(self, op, **fields):
        """One request to the bench process (see bench.py); its answer as a dict. Each request
        carries a number its answer repeats, so a late answer is never taken for the next one's."""
        if self._proc is None or self._proc.poll() is not None:
            raise UserError("the emulated Pico is not running")
        with self._lock:
            self._asked += 1
            self._proc.stdin.write((json.dumps(dict(fields, op=op, id=self._asked)) + "\n").encode())
            self._proc.stdin.flush()
            deadline = time.monotonic() + 30
            while True:
                line = self._read_line(max(0.0, deadline - time.monotonic()))
                if not line:
                    raise UserError("the emulated Pico's bench did not answer %s" % op)
                answer = json.loads(line)
                if answer.pop("id", None) == self._asked:
                    break
        if "error" in answer:
            raise UserError("the emulated Pico's bench refused %s: %s" % (op, answer["error"]))
        return answer

    def rig(self, rig):
        """Apply what a person mounts or hooks (boards/sim/bench_rig.apply's dict) to the actuator."""
        return self.ask("rig", rig=rig)

    def set_load(self, load):
        self.load = dict(load)
        return self.rig({"load": self.load})

    def gauge(self, beat=None):
        """The force gauge's display now: {"force_n", "t_s"} (`beat`, e.g. client.heartbeat_if_due,
        is called first: the same signature as the unix-port board's, which may wait)."""
        if beat is not None:
            beat()
        return self.ask("gauge")

    def state(self):
        return self.ask("state")

    def stop(self):
        proc, self._proc = self._proc, None
        if proc is not None:
            try:
                if proc.poll() is None:
                    proc.stdin.write(b'{"op": "quit"}\n')
                    proc.stdin.flush()
                    proc.wait(timeout=10)
            except (OSError, subprocess.TimeoutExpired, ValueError):
                proc.kill()
                proc.wait()
            for stream in (proc.stdin, proc.stdout):
                try:
                    stream.close()
                except OSError:
                    pass
        if self._config_file:
            try:
                os.unlink(self._config_file)
            except OSError:
                pass
            self._config_file = None
        if self._own_image and self.flash_image is not None:
            try:
                self.flash_image.unlink()
            except OSError:
                pass

    def __enter__(self):
        try:
            self.start()
        except BaseException:
            self.stop()
            raise
        return self

    def __exit__(self, *exc):
        self.stop()
