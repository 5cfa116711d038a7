"""One connection to the board for a whole guided calibration, including re-flashing it.

`--port sim` starts a virtual board here (not through open_board) because the calibration needs
its filesystem root for the rig and must keep it alive while the client is closed for a flash.
After each accepted step the calibration file is installed with host.link.flashing.flash (mpremote,
CRC check, soft reset) and the firmware must answer with the file's CRC.
"""

from pathlib import Path

from host.link.board_client import BoardClient
from host.errors import UserError
from host.link.flashing import REPO, resolve_board


class Session:
    def __init__(self, port, board=None, calibration=None, say=print):
        from host.link.ports import resolve

        self.port = resolve(port)
        self.board_arg = board
        self.calibration = Path(calibration) if calibration else None
        self.say = say
        self.virtual = None
        self.path = None
        self.client = None
        self.board_path = None
        self.board = None

    @property
    def root(self):
        return self.virtual.root if self.virtual is not None else None

    def __enter__(self):
        if self.port == "sim":
            from host.link.virtual_board import VirtualBoard

            self.board_path, self.board = resolve_board(self.board_arg or str(REPO / "boards" / "sim.json"))
            if not self.board.get("simulated"):
                raise UserError("--port sim needs a simulated board file, not %s" % self.board_path)
            existing = self.calibration if self.calibration and self.calibration.is_file() else None
            self.virtual = VirtualBoard(board=self.board_path, calibration=existing)
            self.path = self.virtual.start()
            self.say("virtual board started on %s (filesystem %s)" % (self.path, self.virtual.root))
        else:
            self.path = self.port
        try:
            self.client = BoardClient(self.path)
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
            self.client.close()
            self.client = None
        if self.virtual is not None:
            self.virtual.stop()
            self.virtual = None

    def __exit__(self, *exc):
        self.close()

    def flash(self, calibration):
        """Install `calibration` on the board; returns the CRC the firmware reports."""
        from host.calibration.file import read_calibration
        from host.link.flashing import flash

        read_calibration(calibration)  # refuse a corrupt file before touching the board
        crc_file = file_crc32(calibration)
        self.client.close()
        self.client = None
        status = flash(self.path, str(self.board_path), str(calibration), progress=lambda m: self.say("  flash: " + m),
                       ask_board=False)  # this session identified the board when it opened
        self.client = BoardClient(self.path)
        got = self.client.status_info.get("calibration_crc")
        if got != crc_file:
            raise UserError("the board reports calibration crc %s, the file has %s" % (got, crc_file))
        self.say("  the firmware runs calibration crc %08x" % got)
        return got, status


    def flash_board(self, board_path):
        """Install the firmware with board file `board_path` (the calibration on the board stays)
        and use that board file from now on; returns the firmware's status."""
        from host.link.flashing import flash

        self.client.close()
        self.client = None
        status = flash(self.path, str(board_path), None, progress=lambda m: self.say("  flash: " + m), ask_board=False)
        self.board_path, self.board = resolve_board(str(board_path))
        self.client = BoardClient(self.path)
        return status


def file_crc32(path):
    """The CRC the firmware reports for the calibration file at `path` (its envelope's crc32)."""
    import json

    return json.loads(Path(path).read_text())["crc32"]
