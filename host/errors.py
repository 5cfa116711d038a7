"""The one exception type a person at the bench is meant to read.

Raise `UserError` for anything the user can fix (a bad file, a missing column, a busy port):
the CLI prints its message on one line and exits with status 2, never a traceback.
"""

# A command's exit status means the same in every command (`host --help` says it):
DONE = 0  # what was asked is done
MISSED = 1  # measured, and what was asked not reached or cut off; what was measured is kept
USER_ERROR = 2  # the input or the setup (an option, a file, a port, a check that refused): one line says what
INTERRUPTED = 130  # Ctrl-C, the shell's 128 + SIGINT
CLOSED_PIPE = 141  # the reader of the output went away (`host status | head -3`), the shell's 128 + SIGPIPE
EXIT_STATUSES = ((DONE, "done"),
                 (MISSED, "measured, and the goal missed or the run cut off, what was measured kept (move or force "
                          "not settled, no gain set settled, nothing accepted, a calibration or experiment stopped "
                          "partway)"),
                 (USER_ERROR, "the input or the setup, one line saying what to fix (a bad option, file or port, a "
                              "board lost before anything was measured, a check that refused)"),
                 (INTERRUPTED, "Ctrl-C"), (CLOSED_PIPE, "the output's reader went away (| head)"))


class UserError(Exception):
    """An error caused by input or environment, with a message that says what to do."""


class LinkError(UserError, TimeoutError):
    """The link to the board failed: no reply in time, or the port vanished (unplugged). A
    UserError, so a command says it in one line with exit status 2, and a TimeoutError (an
    OSError), so code that waits for a board can tell it from a refusal or a bad file."""


def os_error_line(exc):
    """The one line for an OSError that no command turned into a UserError: a serial port's says
    the board may be gone; one with a file names the file and what the system said (a full disk,
    a directory where a file was meant, no permission); any other is said as it is."""
    try:
        from serial import SerialException
    except ImportError:  # pragma: no cover (pyserial is a dependency)
        SerialException = ()
    import errno

    said = str(exc).strip() or type(exc).__name__
    if exc.filename is not None:
        return "%s: %s" % (exc.filename, exc.strerror or said)
    if isinstance(exc, SerialException) or exc.errno in (errno.EIO, errno.ENXIO, errno.ENODEV):
        return "%s (the board stopped answering or was unplugged?)" % said  # what a vanished port reads
    return said


def check_user_file(path, what, max_bytes):
    """Refuse, before reading it, a file a person named that cannot be `what` (e.g. "calibration
    file"): missing, a directory, not a regular file (a FIFO or /dev/zero, which never end), or
    larger than `max_bytes` (no such file is that large; reading it would only take the memory)."""
    import os
    import stat

    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise UserError("no %s at %s" % (what, path)) from None
    except OSError as exc:
        raise UserError("cannot read %s %s: %s" % (what, path, exc.strerror or exc)) from None
    if stat.S_ISDIR(st.st_mode):
        raise UserError("%s is a directory, not a %s" % (path, what))
    if not stat.S_ISREG(st.st_mode):
        raise UserError("%s is not a regular file (a device or a pipe?), not a %s" % (path, what))
    if st.st_size > max_bytes:
        raise UserError("%s is %d bytes, larger than any %s (at most %d)" % (path, st.st_size, what, max_bytes))


def check_output_file(path, what, make_folders=False):
    """Refuse, before any work, a path a `what` (e.g. "calibration file") cannot be written to: a
    directory, a folder that does not exist (unless the command makes its folders: then the
    nearest one that does exist counts), or a folder this user cannot write (read-only, another
    user's). A calibration that fails here costs a keystroke; one that fails when it is saved
    costs the measuring before it."""
    import os
    from pathlib import Path

    path = Path(path)
    if path.is_dir():
        raise UserError("%s is a directory, not a %s" % (path, what))
    folder = path.absolute().parent
    if not folder.exists() and not make_folders:
        raise UserError("cannot write %s %s: no folder %s" % (what, path, folder))
    while not folder.exists():
        folder = folder.parent
    if not folder.is_dir():
        raise UserError("cannot write %s %s: %s is a file, not a folder" % (what, path, folder))
    if not os.access(folder, os.W_OK | os.X_OK) or (path.exists() and not os.access(path, os.W_OK)):
        raise UserError("cannot write %s %s: %s is not writable here (read-only, or another user's)"
                        % (what, path, path if path.exists() else folder))


def _installed_from():
    """Where pip installed this package from when it was a local directory (PEP 610's
    direct_url.json), else None (an index, a wheel file, or no record)."""
    import json
    from importlib import metadata
    from urllib.parse import unquote, urlparse

    try:
        record = json.loads(metadata.distribution("lsea-kit").read_text("direct_url.json") or "{}")
    except (metadata.PackageNotFoundError, ValueError):
        return None
    url = urlparse(record.get("url", ""))
    return unquote(url.path) if url.scheme == "file" and "dir_info" in record else None


def install_hint(extra=None):
    """The command that installs what is missing, for the way this copy was installed: from a
    source checkout (running from it, or installed editable), from a local directory (pip
    install DIR), or from a package index."""
    from pathlib import Path

    what = "[%s]" % extra if extra else ""
    tree = Path(__file__).resolve().parent.parent
    if (tree / "pyproject.toml").is_file():  # the code runs from a source checkout
        return "pip install -e '%s%s'" % (tree, what)
    source = _installed_from()
    if source is not None:
        return "pip install '%s%s'" % (source, what)
    return "pip install 'lsea-kit%s'" % what
