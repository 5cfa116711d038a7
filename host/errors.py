"""The one exception type a person at the bench is meant to read.

Raise `UserError` for anything the user can fix (a bad file, a missing column, a busy port):
the CLI prints its message on one line and exits with status 2, never a traceback.
"""


class UserError(Exception):
    """An error caused by input or environment, with a message that says what to do."""
