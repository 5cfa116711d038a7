"""Terminal manners: progress and warnings on stderr (--quiet silences progress, never a warning),
results on stdout; a guided run's talk with its person on stderr (`tell`; with --yes nobody is
asking, and it is progress).

On a terminal a progress line is rewritten in place (`\\r`); written to a file or a pipe each
update is a line of its own, at most one a `every` seconds, so a saved log stays readable.
"""

import sys
import time

_state = {"open": False, "last": 0.0, "quiet": False}


def set_quiet(flag):
    """`host --quiet`: no progress lines at all (a script reads results from stdout)."""
    _state["quiet"] = bool(flag)


def _tty():
    try:
        return sys.stderr.isatty()
    except (AttributeError, ValueError):
        return False


def progress_line(text, every=0.0):
    """Show `text` as the current progress; `every` limits how often it is written off a terminal."""
    if _state["quiet"]:
        return
    if _tty():
        sys.stderr.write("\r" + text[:110].ljust(110))
        _state["open"] = True
    else:
        now = time.monotonic()
        if every and now - _state["last"] < every:
            return
        _state["last"] = now
        sys.stderr.write(text.rstrip() + "\n")
    sys.stderr.flush()


def live(text):
    """A status worth seeing only as it changes (which order a fit is at): rewritten in place on a
    terminal, not written at all to a file or a pipe, where the lines that follow say the same."""
    if _tty():
        progress_line(text)


def note(text):
    """A progress message on a line of its own on stderr (nothing under --quiet)."""
    if not _state["quiet"]:
        print(text, file=sys.stderr, flush=True)


def output(text=""):
    """A result: on stdout, what a script reads (never silenced)."""
    end_progress()
    print(text, flush=True)


def error(text):
    """`error: text` on stderr, the one line a failed command ends with."""
    end_progress()
    print("error: " + text, file=sys.stderr, flush=True)


def interrupted():
    """`interrupted` on stderr: how a command stopped by Ctrl-C ends."""
    end_progress()
    print("interrupted", file=sys.stderr, flush=True)


def tell(text):
    """A line for the person at the bench (a guided run's instructions and each step's figures,
    which they judge before answering) on stderr: also under --quiet while someone answers."""
    end_progress()
    print(text, file=sys.stderr, flush=True)


def warn(text):
    """`warning: text` on stderr, on a line of its own: also under --quiet, which silences progress,
    never what a person must know about the result."""
    end_progress()
    print("warning: " + text, file=sys.stderr, flush=True)


def end_progress():
    """Finish the progress line (a newline on a terminal, nothing to do elsewhere)."""
    if _state["open"]:
        sys.stderr.write("\n")
        sys.stderr.flush()
        _state["open"] = False
    _state["last"] = 0.0
