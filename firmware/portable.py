"""What lets one firmware source run under MicroPython and, for tests, under CPython.

`const` comes from MicroPython where it exists; `ptr32` stands in for viper's cast under CPython. The code emitters are NOT run-time functions:
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


def ptr32(buf):
    """CPython stand-in for viper's ptr32 cast: the buffer's memory as signed 32-bit words.

    Under MicroPython viper resolves `ptr32` itself (this function is never called there). A
    list (the host's exported constants, possibly of tracked ints) is used as it is."""
    if isinstance(buf, list):
        return buf
    return memoryview(buf).cast("B").cast("i")


def native(func):
    """CPython stand-in for @micropython.native (never reached on MicroPython, see above)."""
    return func


def viper(func):
    """CPython stand-in for @micropython.viper (never reached on MicroPython, see above)."""
    return func
