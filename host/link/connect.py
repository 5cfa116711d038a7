"""Where a command finds its board: one function for every `--port` (a serial device, `auto`,
`sim`, `sim:rp2040`).

`open_port(port, ...)` resolves the port (`auto`: the one board `host ports` finds) and, for
`sim`, starts a virtual board for the life of the context (the firmware on the MicroPython unix
port, host/link/virtual_board.py); for `sim:rp2040` an emulated Pico (the Pico's MicroPython on
rp2040js, host/link/emulated_pico/), onto which the firmware is installed the way it is onto a
real Pico, by `host flash` over its USB serial. Either one's serial path, rig and board file stay
valid while clients come and go, so a guided calibration can close its client, flash the board
and open a new one.
`Connection(port, ...)` is open_port with a BoardClient on it (the handshake done), and the one
way a command or the guided calibration talks to a board, streams its telemetry to sinks
(stream(), tee()), re-flashes it and reconnects (with check=False, the client's own handshake()
asks what runs there: host ports --probe, host flash).
"""

import contextlib
from pathlib import Path

from host.errors import UserError
from host.link.board_client import BoardClient
from host.link.stream import Tee, records

SIM = "sim"
CHIPS = ("rp2040",)  # --port sim:CHIP: an emulated chip running the board's own MicroPython


def virtual_kind(port):
    """None for a port that is not a virtual board, "" for `sim`, the chip for `sim:CHIP`."""
    kind, sep, chip = str(port).partition(":")
    if kind != SIM:
        return None
    if sep and chip not in CHIPS:
        raise UserError("unknown emulated chip in --port %s: sim (the MicroPython unix port) or %s"
                        % (port, ", ".join("sim:" + c for c in CHIPS)))
    return chip


class BoardPort:
    """The serial path of a board for one command; for `sim` the virtual board behind it."""

    def __init__(self, port, board=None, calibration=None, load=None, factory=True, uf2=None, progress=None, ready=False,
                 root=None, actuator=None, flash_image=None):
        from host.link.ports import resolve

        self.port = resolve(port)
        self.board = board
        self.calibration = calibration
        self.load = load
        self.factory = factory
        self.uf2 = uf2
        self.progress = progress
        self.ready = ready  # a unix-port virtual board of boards/sim.json starts calibrated
        self.flash_dir = root  # a unix-port virtual board's flash directory (None: a temp dir)
        self.actuator = actuator  # an emulated Pico's simulated actuator (a board file; None: boards/sim.json's)
        self.flash_image = flash_image  # an emulated Pico's filesystem, kept in this file (None: fresh each run)
        self.virtual = None
        self.path = None

    @property
    def root(self):
        """The virtual board's filesystem (its flash), or None on a real board."""
        return self.virtual.root if self.virtual is not None else None

    @property
    def board_path(self):
        """The virtual board's board file, or None on a real board (its firmware says which it is)."""
        return self.virtual.board_path if self.virtual is not None else None

    def open(self):
        chip = virtual_kind(self.port)
        if chip is None:
            self.path = self.port
            self.virtual = _attached(self.path)
            if self.load is not None:
                if self.virtual is None:
                    raise UserError("a load can be hooked only on a virtual board (port sim); on a bench, hook it by hand")
                self.virtual.set_load(self.load)
            return self
        if self.calibration is not None:  # for either board started here: a file it could not use, named now
            from host.calibration.file import read_calibration

            if not Path(self.calibration).exists():
                raise UserError("calibration file not found: %s" % self.calibration)
            read_calibration(self.calibration)
        if chip == "rp2040":
            return self._open_pico()
        from host.link.flashing import resolve_board
        from host.link.virtual_board import DEFAULT_BOARD, VirtualBoard, ready_calibration

        board_path, board = resolve_board(self.board or str(DEFAULT_BOARD))
        if not board.get("simulated"):
            raise UserError("a virtual board needs a simulated board file, not %s" % board_path)
        calibration = self.calibration
        if calibration is None and self.ready and self.factory:
            calibration = ready_calibration(board_path)
        self.virtual = VirtualBoard(board=board_path, calibration=calibration, load=self.load,
                                    factory=self.factory, root=self.flash_dir)
        self.path = self.virtual.start()
        return self

    def _open_pico(self):
        from host.link.emulated_pico.board import SIM_BOARD, EmulatedPico, default_board
        from host.link.flashing import flash, resolve_board

        board_path, board = resolve_board(self.board or str(default_board(self.uf2)))
        if board.get("mcu") != "RP2040":
            raise UserError("an emulated Pico runs an RP2040 board file, not %s (mcu %s)" % (board_path, board.get("mcu")))
        say = self.progress or _note
        self.virtual = EmulatedPico(uf2=self.uf2, board=board_path, actuator=self.actuator or SIM_BOARD,
                                    flash_image=self.flash_image, load=self.load, log=say)
        self.path = self.virtual.start()
        if self.factory:  # as a person does with a new Pico: host flash, over its USB serial
            say("emulated Pico on %s: installing the firmware with host flash" % self.path)
            flash(self.path, str(board_path), self.calibration, progress=lambda m: say("  flash: " + m), ask_board=False)
        return self

    def close(self):
        if self.virtual is not None:
            self.virtual.stop()
            self.virtual = None

    def __enter__(self):
        try:
            return self.open()
        except BaseException:
            self.close()
            raise

    def __exit__(self, *exc):
        self.close()


def _note(text):
    from host.terminal import note

    note(text)


def _attached(path):
    """The virtual board `host sim` runs on serial path `path` (unix port), for its rig and gauge:
    not started here and not stopped by close(); None for any other port."""
    from host.link.running_sims import record_for

    record = record_for(path)
    if not record or not record.get("root") or not record.get("board"):
        return None
    from host.link.virtual_board import VirtualBoard

    return VirtualBoard(board=record["board"], root=record["root"])


def open_port(port, board=None, calibration=None, load=None, factory=True, uf2=None, progress=None, ready=False,
              root=None, actuator=None, flash_image=None):
    """A BoardPort for `port` (use as a context manager): a device path as it is, `auto` resolved,
    `sim` a virtual board with `board` (name or file, default boards/sim.json), `calibration` on
    its flash and `load` (a host.link.bench_load.parse_load dict) hooked on its block;
    `sim:rp2040` an emulated Pico running the MicroPython `uf2` (default $LSEA_PICO_UF2) with
    `board` (default boards/pico.json), our firmware and `calibration` installed by host flash;
    `factory=False` leaves its flash empty (for `host flash`). `progress(text)`: what a starting
    emulated Pico says (default: progress lines on stderr). `ready`: a `sim` board of
    boards/sim.json without `calibration` gets the shipped one (virtual_board.READY_CALIBRATION)
    instead of starting uncalibrated. `root` (sim: its flash directory), `actuator` and
    `flash_image` (sim:rp2040: the simulated actuator wired to it, its filesystem kept in a file):
    what `host sim` offers."""
    return BoardPort(port, board, calibration, load, factory, uf2, progress, ready, root, actuator, flash_image)


def ask_firmware(port):
    """What lsea-kit firmware on `port` says it is: (its hello, None), or (None, why nothing of
    ours answers). A port that will not open raises (UserError, OSError): that is for the user
    to fix. The one way to ask a port what runs there (host flash before installing, host ports
    --probe)."""
    with Connection(port, check=False) as connection:  # check=False: a board may have no firmware yet
        try:
            return connection.client.handshake(), None
        except (UserError, OSError) as exc:
            return None, str(exc)


class Connection:
    """One connection to a board, the one every command and the guided calibration use: the
    resolved port (open_port: a board started for the command stays alive behind it), the
    BoardClient on it (handshake done), and what changes it: reconnect() and reflash(). Use as a
    context manager (it returns itself) or open()/close(); closing stops nothing on the board
    (the caller stops what it started)."""

    def __init__(self, port, board=None, calibration=None, load=None, uf2=None, ready=True, factory=True,
                 progress=None, **client_options):
        """`ready`: a `sim` board of boards/sim.json starts with the shipped calibration unless
        `calibration` is given (open_port); False: uncalibrated, as from the factory.
        `client_options`: BoardClient's (check, require_calibration, ...)."""
        self.where = open_port(port, board, calibration, load, factory=factory, uf2=uf2, progress=progress, ready=ready)
        self.options = client_options
        self.client = None
        self._tee = None

    @property
    def virtual(self):
        """The board started for this connection (VirtualBoard or EmulatedPico), else None."""
        return self.where.virtual

    @property
    def path(self):
        """The serial device (the pty of a board started for this connection)."""
        return self.where.path

    @property
    def board_path(self):
        """The board file a board started for this connection runs, else None."""
        return self.where.board_path

    @property
    def link(self):
        """What a reader streams through: the client, or while tee() is on, the Tee in its place."""
        return self._tee if self._tee is not None else self.client

    @contextlib.contextmanager
    def tee(self, rate=1000, sinks=(), stop=None):
        """Within the block the board streams at `rate` Hz and every frame read through `link`
        (a motion's settle, stream(), the Tee's own pump) goes to each of `sinks` first: a motion
        and its log share this connection. Yields the host.link.stream.Tee (its .summary counts
        what went to the sinks; .pump() only streams). `stop`: see Tee."""
        if self._tee is not None:
            raise RuntimeError("a tee is on already: give it every sink")
        with Tee(self.client, rate, sinks, stop) as tee:
            self._tee = tee
            try:
                yield tee
            finally:
                self._tee = None

    def stream(self, seconds, rate=1000, sinks=()):
        """Telemetry for `seconds` of the board's time at `rate` Hz (through a tee, if one is on),
        each frame's records handed to each of `sinks` (host.link.stream: CsvLog, Arrays, any
        callable); returns the board seconds streamed (the last frame may reach past `seconds`: the
        sinks get its records up to `seconds`)."""
        streamed = 0.0
        for _rows, board_s in records(self.link, seconds, rate, sinks=sinks):
            streamed = board_s
        return streamed

    def open(self):
        self.where.open()
        try:
            self.client = BoardClient(self.where.path, **self.options)
        except BaseException:
            self.where.close()
            raise
        return self

    def reconnect(self):
        """A new client on the same port (after the board restarted); returns it."""
        if self._tee is not None:
            raise RuntimeError("reconnecting under a tee would leave it on the old client")
        if self.client is not None:
            self.client.close()
        self.client = None
        self.client = BoardClient(self.where.path, **self.options)
        return self.client

    def reflash(self, board_path=None, calibration=None, progress=None, ask_board=None, **flash_options):
        """`host flash` over this connection: the client closed, the firmware, the board file
        (default: that of a board started for this connection) and `calibration` installed, a new
        client. `ask_board` (default: on a real board) checks the board file against what the
        board says it is; `flash_options`: flashing.flash's (replace_board, force). Returns the
        firmware's status after."""
        from host.link.flashing import flash

        if board_path is None and self.board_path is not None:
            board_path = self.board_path
        if ask_board is None:
            ask_board = self.virtual is None
        if self.client is not None:
            self.client.close()
            self.client = None
        try:
            status = flash(self.path, None if board_path is None else str(board_path),
                           None if calibration is None else str(calibration),
                           progress=progress or (lambda text: None), ask_board=ask_board, **flash_options)
        except BaseException:
            try:
                self.reconnect()  # to what the board runs now, if it answers
            except Exception:
                pass  # the flash's own error is the one to report (a vanished port would hide it)
            raise
        self.reconnect()
        return status

    def close(self):
        try:
            if self.client is not None:
                self.client.close()
                self.client = None
        finally:
            self.where.close()

    def __enter__(self):
        return self.open()

    def __exit__(self, *exc):
        self.close()
