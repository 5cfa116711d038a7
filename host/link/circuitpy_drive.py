"""`host flash --drive`: the firmware onto a CircuitPython board's mounted CIRCUITPY drive, the way
its owners install code, for a board whose drive a computer has mounted (CircuitPython then
refuses code that writes it, so the raw REPL cannot; host/link/flashing.py does that otherwise).

The same files as over the serial link (firmware_files.build: plain source, code.py, the board file,
the calibration), each checked first (flashing.check_files). Each is written beside its place as
NAME.new, flushed to the drive, then renamed over the old one: FAT has no atomic rename, but a
file is never left half-written under its own name. The calibration goes last and the old one is
kept as calibration.json.old until the new one is in place, as on the serial path, so that the
firmware's boot (board_main.recover_calibration) puts it back if the copy stops between the two.
Every file is read back and compared. CircuitPython reloads code.py by itself when the drive
changes."""

import binascii
import os
import tempfile
from pathlib import Path

from host.errors import UserError, os_error_line
from host.link.firmware_files import build, circuitpython
from host.link.flashing import check_files, resolve_board

MARK = "boot_out.txt"  # CircuitPython writes it at every boot: a CIRCUITPY drive has it


def install(drive, board_name, calibration=None, progress=None, force=False):
    """Install on the mounted drive `drive`; returns [(board path, CRC-32)] of the files, verified."""
    progress = progress or (lambda text: None)
    drive = Path(drive)
    if not (drive / MARK).is_file():
        raise UserError("%s is not a CircuitPython drive (no %s): give the mounted CIRCUITPY drive" % (drive, MARK))
    board_path, board = resolve_board(board_name)
    if not circuitpython(board):
        raise UserError("board %s is not for CircuitPython: --drive installs boards with \"runtime\": \"circuitpython\"" % board["name"])
    check_files(board_path, calibration, force)
    with tempfile.TemporaryDirectory(prefix="lsea-drive-") as tmp:
        files = build(board, tmp) + [(Path(board_path), "board.json")]
        if calibration is not None:
            files.append((Path(calibration), "calibration.json"))  # last: the old one stays until then
        progress("copying %d files to %s" % (len(files), drive))
        written = []
        try:
            for src, dst in files:
                written.append((dst, _put(Path(src).read_bytes(), drive / dst)))
        except OSError as exc:
            raise UserError(os_error_line(exc)) from None
    progress("verifying")
    for dst, crc in written:
        got = binascii.crc32((drive / dst).read_bytes())
        if got != crc:
            raise UserError("verification failed: %s on %s has CRC %d, expected %d" % (dst, drive, got, crc))
    return written


def _put(data, path):
    """Write `data` to `path` by way of PATH.new (calibration.json: the old kept as .old until
    the new one is in place); returns its CRC-32."""
    path.parent.mkdir(parents=True, exist_ok=True)
    new = path.with_name(path.name + ".new")
    with open(new, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())
    if path.name == "calibration.json" and path.exists():
        old = path.with_name(path.name + ".old")
        os.replace(path, old)
        os.replace(new, path)
        os.remove(old)
    else:
        os.replace(new, path)
    return binascii.crc32(data)
