"""What lets one firmware source run under MicroPython and, for tests, under CPython.

`const` and `ticks_us` come from MicroPython where they exist; `ptr32` stands in for viper's
cast under CPython; `release` lets a board's heap take back a module only the boot needs. The
code emitters are NOT run-time functions: MicroPython's compiler selects them only for the
literal decorators `@micropython.native` and `@micropython.viper`. A module that wants one
therefore writes

    try:
        import micropython
    except ImportError:  # CPython
        from firmware import portable as micropython

    @micropython.native
    def f(...): ...

and under CPython this module stands in for `micropython` with identity decorators.
"""

import sys
from array import array

try:
    from micropython import const  # noqa: F401
except ImportError:  # CPython

    def const(value):
        return value

try:
    from time import ticks_us  # noqa: F401  (MicroPython: a 30-bit wrapping microsecond clock)
except ImportError:  # CPython
    import time as _time

    def ticks_us():
        return (_time.perf_counter_ns() // 1000) & 0x3FFFFFFF


def zeros(n, typecode="i"):
    """array(typecode) of n zeros, built without a throw-away list as large as itself (on a
    board's small heap such a list costs as much again as the array and fragments the rest)."""
    a = array(typecode, range(n))
    i = 0
    while i < n:
        a[i] = 0
        i += 1
    return a


def word_property(i, writable=False):
    """A property over word `i` of the instance's int32 block `st` (each module keeps its state
    there, so viper code can reach it through one ptr32), read-only unless `writable`."""

    def get(self):
        return self.st[i]

    if not writable:
        return property(get)

    def put(self, v):
        self.st[i] = v

    return property(get, put)


def ptr32(buf):
    """CPython stand-in for viper's ptr32 cast: the buffer's memory as signed 32-bit words.

    Under MicroPython viper resolves `ptr32` itself (this function is never called there). A
    list (the host's exported constants, possibly of tracked ints) is used as it is."""
    if isinstance(buf, list):
        return buf
    return memoryview(buf).cast("B").cast("i")


def ptr16(buf):
    """CPython stand-in for viper's ptr16 cast: the buffer's memory as unsigned 16-bit words."""
    return memoryview(buf).cast("B").cast("H")


def native(func):
    """CPython stand-in for @micropython.native (never reached on MicroPython, see above)."""
    return func


def viper(func):
    """CPython stand-in for @micropython.viper (never reached on MicroPython, see above)."""
    return func


def release(name):
    """Let the garbage collector take back module `name` (e.g. "firmware.calibration"), which only
    the boot needed: MicroPython keeps a module's code in the heap, so a board drops it from
    sys.modules and from its package once it is done with it. The caller keeps nothing of it but
    data (no function, no instance of a class with methods: either would keep the module's
    globals, and so all its code, alive). A later import loads it again. Under CPython (the host
    and the tests) nothing is released: host code holds these modules, and a second copy would
    bring a second CalibrationError class."""
    if sys.implementation.name != "micropython":
        return
    sys.modules.pop(name, None)
    dot = name.rfind(".")
    outer = sys.modules.get(name[:dot])
    try:
        delattr(outer, name[dot + 1 :])
    except (AttributeError, KeyError):  # not imported, or already released (KeyError: MicroPython)
        pass
