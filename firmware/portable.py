"""What lets one firmware source run under MicroPython and, for tests, under CPython.

`const` comes from MicroPython where it exists. The code emitters are NOT run-time functions:
MicroPython's compiler selects them only for the literal decorators `@micropython.native` and
`@micropython.viper`. A module that wants one therefore writes

    try:
        import micropython
    except ImportError:  # CPython
        from firmware import portable as micropython

    @micropython.native
    def f(...): ...

and under CPython this module stands in for `micropython` with identity decorators.
"""

try:
    from micropython import const  # noqa: F401
except ImportError:  # CPython

    def const(value):
        return value


def native(func):
    """CPython stand-in for @micropython.native (never reached on MicroPython, see above)."""
    return func


def viper(func):
    """CPython stand-in for @micropython.viper (never reached on MicroPython, see above)."""
    return func
