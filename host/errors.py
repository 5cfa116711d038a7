"""The one exception type a person at the bench is meant to read.

Raise `UserError` for anything the user can fix (a bad file, a missing column, a busy port):
the CLI prints its message on one line and exits with status 2, never a traceback.
"""


class UserError(Exception):
    """An error caused by input or environment, with a message that says what to do."""


def install_hint(extra=None):
    """The command that installs what is missing, for the way this copy was installed: an
    editable source checkout (pip install -e) or an installed package."""
    from pathlib import Path

    checkout = (Path(__file__).resolve().parent.parent / "pyproject.toml").is_file()
    what = ".[%s]" % extra if extra else "."
    if checkout:
        return "pip install -e '%s'" % what
    return "pip install 'lsea-kit%s'" % ("[%s]" % extra if extra else "")
