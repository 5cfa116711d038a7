"""The virtual boards `host sim` is running on this machine, so that `host ports` lists them and
`--port auto` finds one, as it finds a board on USB.

Each `host sim` writes a small record (its pty, what runs behind it, its process id) into
run_dir() while it runs and removes it when it stops; a record whose process is gone (a `host sim`
killed with SIGKILL) is ignored and removed by the next reader.
"""

import json
import os
import tempfile
from pathlib import Path


def run_dir():
    """Where the records live: the user's runtime directory (XDG_RUNTIME_DIR), else the temp dir."""
    return Path(os.environ.get("XDG_RUNTIME_DIR") or tempfile.gettempdir()) / ("lsea-kit-sims-%d" % os.getuid())


def _alive(pid):
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's process: alive
        return True
    return True


def register(path, what, root=None, board=None):
    """Record a running virtual board on serial path `path` (`root`: its flash folder, where its
    rig is mounted; `board`: its board file); returns the record's file (remove it with
    unregister when the board stops)."""
    folder = run_dir()
    folder.mkdir(mode=0o700, parents=True, exist_ok=True)
    record = folder / ("%d.json" % os.getpid())
    tmp = record.with_suffix(".tmp")
    tmp.write_text(json.dumps({"path": str(path), "what": what, "pid": os.getpid(),
                               "root": None if root is None else str(root), "board": None if board is None else str(board)}))
    os.replace(tmp, record)
    return record


def unregister(record):
    try:
        os.unlink(record)
    except OSError:
        pass


def record_for(path):
    """The record (dict: path, what, pid, root, board) of the virtual board running on serial
    path `path`, or None."""
    for record in _records():
        if os.path.realpath(record["path"]) == os.path.realpath(str(path)):
            return record
    return None


def running():
    """[(serial path, what)] of the virtual boards running now (stale records removed)."""
    return [(r["path"], str(r.get("what", "virtual board"))) for r in _records()]


def _records():
    out = []
    folder = run_dir()
    for record in sorted(folder.glob("*.json")) if folder.is_dir() else []:
        try:
            data = json.loads(record.read_text())
            pid, path = int(data["pid"]), str(data["path"])
        except (OSError, ValueError, KeyError, TypeError):
            continue
        if not _alive(pid) or not os.path.exists(path):
            unregister(record)
            continue
        out.append(data)
    return out
