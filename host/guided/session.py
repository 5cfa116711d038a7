"""One connection to the board for a whole guided calibration, including re-flashing it.

The board is opened as a host.link.connect.Connection, which keeps a virtual board (`sim`) and
its filesystem root (where the rig is mounted) alive while it re-flashes. After each accepted
step the calibration file is installed with Connection.reflash (host flash: mpremote, CRC
check, soft reset) and the firmware must answer with the file's CRC. The session adds what a
calibration needs: the board file it calibrates for, and the simulated actuator if there is one.
"""

from pathlib import Path

from host.errors import UserError
from host.link.connect import Connection
from host.link.flashing import resolve_board


class Session:
    def __init__(self, port, board=None, calibration=None, say=None, uf2=None):
        self.board_arg = board
        self.calibration = Path(calibration) if calibration else None
        if say is None:
            from host.terminal import note as say
        self.say = say
        existing = self.calibration if self.calibration and self.calibration.is_file() else None
        self.connection = Connection(port, board, existing, uf2=uf2, progress=say)
        self.port = self.connection.where.port
        self.board_path = None
        self.board = None

    @property
    def client(self):
        """The BoardClient of the moment (a new one after each flash)."""
        return self.connection.client

    @property
    def path(self):
        return self.connection.path

    @property
    def virtual(self):
        return self.connection.virtual

    @property
    def root(self):
        return self.connection.where.root

    @property
    def actuator(self):
        """The simulated actuator's description on a virtual board (also one started elsewhere,
        `host sim`, whose board file says it is simulated), None on a real one."""
        if self.virtual is not None:
            return self.virtual.actuator
        if self.board is not None and self.board.get("simulated"):
            return self.board.get("actuator")
        return None

    @property
    def simulated(self):
        """Whether the actuator behind this board is the simulated one."""
        return self.actuator is not None

    def __enter__(self):
        try:
            self.connection.open()
            if self.virtual is not None:
                if self.root is not None:
                    self.say("virtual board started on %s (filesystem %s)" % (self.path, self.root))
                else:
                    self.say("emulated %s started on %s" % (self.virtual.chip, self.path))
                self.board_path, self.board = resolve_board(str(self.connection.board_path))
            if self.board is None:
                self.board_path, self.board = resolve_board(self.board_arg or self.client.status_info["board"])
        except BaseException:
            self.close()
            raise
        return self

    def close(self):
        if self.client is not None:
            try:
                self.client.call("stop")
            except Exception:
                pass
        self.connection.close()

    def __exit__(self, *exc):
        self.close()

    def flash(self, calibration):
        """Install `calibration` on the board; returns the CRC the firmware reports."""
        from host.calibration.file import read_calibration

        _, crc_file = read_calibration(calibration, with_crc=True)  # a corrupt file is refused before the board is touched
        status = self.connection.reflash(self.board_path, calibration, progress=lambda m: self.say("  flash: " + m),
                                         ask_board=False)  # this session identified the board when it opened
        got = status.get("calibration_crc")
        if got != crc_file:
            raise UserError("the board reports calibration crc %s, the file has %s" % (got, crc_file))
        self.say("  the firmware runs calibration crc %08x" % got)
        return got, status


    def flash_board(self, board_path):
        """Install the firmware with board file `board_path` (the calibration on the board stays)
        and use that board file from now on; returns the firmware's status."""
        status = self.connection.reflash(board_path, None, progress=lambda m: self.say("  flash: " + m),
                                         ask_board=False)
        self.board_path, self.board = resolve_board(str(board_path))
        return status
