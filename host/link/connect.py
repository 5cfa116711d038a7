"""Where a command finds its board: one function for every `--port` (a serial device, `auto`, `sim`).

`open_port(port, ...)` resolves the port (`auto`: the one board `host ports` finds) and, for
`sim`, starts a virtual board for the life of the context: its serial path, its filesystem root
(the rig reads what is mounted from there) and its board file stay valid while clients come and
go, so a guided calibration can close its client, flash the board and open a new one.
`open_board(port, ...)` is open_port with a BoardClient on it (the handshake done), for the
commands that only talk to the board; `ask_firmware(port)` is the handshake alone.
"""

from pathlib import Path

from host.errors import UserError
from host.link.board_client import BoardClient

SIM = "sim"


class BoardPort:
    """The serial path of a board for one command; for `sim` the virtual board behind it."""

    def __init__(self, port, board=None, calibration=None, load=None, factory=True):
        from host.link.ports import resolve

        self.port = resolve(port)
        self.board = board
        self.calibration = calibration
        self.load = load
        self.factory = factory
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
        if self.port != SIM:
            if self.load is not None:
                raise UserError("a load can be hooked only on a virtual board (port sim); on a bench, hook it by hand")
            self.path = self.port
            return self
        from host.link.flashing import resolve_board
        from host.link.virtual_board import DEFAULT_BOARD, VirtualBoard

        board_path, board = resolve_board(self.board or str(DEFAULT_BOARD))
        if not board.get("simulated"):
            raise UserError("a virtual board needs a simulated board file, not %s" % board_path)
        if self.calibration is not None and not Path(self.calibration).is_file():
            raise UserError("calibration file not found: %s" % self.calibration)
        self.virtual = VirtualBoard(board=board_path, calibration=self.calibration, load=self.load,
                                    factory=self.factory)
        self.path = self.virtual.start()
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


def open_port(port, board=None, calibration=None, load=None, factory=True):
    """A BoardPort for `port` (use as a context manager): a device path as it is, `auto` resolved,
    `sim` a virtual board with `board` (name or file, default boards/sim.json), `calibration` on
    its flash and `load` (a host.link.virtual_board.parse_load dict) hooked on its block;
    `factory=False` leaves its flash empty (for `host flash`)."""
    return BoardPort(port, board, calibration, load, factory)


class open_board:
    """Context manager: a BoardClient on `port` (any form open_port takes), handshake done."""

    def __init__(self, port, board=None, calibration=None, load=None, **client_options):
        self.where = open_port(port, board, calibration, load)
        self.options = client_options
        self.client = None

    @property
    def virtual(self):
        """The virtual board behind port `sim`, else None."""
        return self.where.virtual

    def __enter__(self):
        self.where.__enter__()
        try:
            self.client = BoardClient(self.where.path, **self.options)
        except BaseException:
            self.where.close()
            raise
        return self.client

    def __exit__(self, *exc):
        try:
            if self.client is not None:
                self.client.close()
        finally:
            self.where.close()


def ask_firmware(port):
    """The status our firmware on serial port `port` answers with (UserError or OSError when
    nothing of ours answers there)."""
    with BoardClient(port, check=False) as client:
        return client.handshake()
