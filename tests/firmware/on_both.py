"""What the tests of the App's cases share: `runner(cases)` makes the `both` they call.

The cases (tests/firmware/app_cases.py, safety_cases.py, drive_cases.py, param_cases.py) run
under CPython and MicroPython; the replay data files they read are the module-scoped fixtures
`data_path` and `bcm3_data_path` of tests/firmware/conftest.py.
"""

from testkit import interpreters


def runner(cases):
    """both(call, data_path=None) for the cases module `cases` (its dotted name): (CPython's
    result, MicroPython's result) of `call`, with PATH in it replaced by repr(data_path)."""

    def both(call, data_path=None):
        return interpreters.both(cases, call.replace("PATH", repr(data_path)))

    return both
