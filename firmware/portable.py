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


def us_from_ms(ticks_ms):
    """A ticks_us made from a millisecond clock `ticks_ms` that wraps at 2**29 (CircuitPython's
    supervisor.ticks_ms): microseconds in whole milliseconds, wrapping at 2**30 as MicroPython's
    ticks_us does, and allocating nothing (the count lives in an array). CircuitPython's only
    finer clock, time.monotonic_ns, makes a long int at every call: two a step were 128 bytes,
    a 12 ms garbage collection every 1.6 s of the loop (docs/circuitpython.md)."""
    clock = array("i", [ticks_ms(), 0])  # the last reading, ms; the count, us mod 2**30

    def ticks_us():
        now = ticks_ms()
        # a gap of up to 18 minutes stays a small int; a longer one makes one long int, still right
        clock[1] = (clock[1] + ((now - clock[0]) & 0x1FFFFFFF) * 1000) & 0x3FFFFFFF
        clock[0] = now
        return clock[1]

    return ticks_us


TICK_US = 1  # the resolution of ticks_us below, us (1000 where it counts whole milliseconds)
try:
    from time import ticks_us  # noqa: F401  (MicroPython: a 30-bit wrapping microsecond clock)
except ImportError:  # CPython, CircuitPython
    try:
        from supervisor import ticks_ms as _ticks_ms  # CircuitPython
    except ImportError:  # CPython
        _ticks_ms = None
    if _ticks_ms is not None:
        ticks_us = us_from_ms(_ticks_ms)
        TICK_US = 1000
    else:
        import time as _time

        _ns = getattr(_time, "perf_counter_ns", None) or _time.monotonic_ns

        def ticks_us():
            return (_ns() // 1000) & 0x3FFFFFFF


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


# MicroPython's and CircuitPython's memoryview has no cast(): there the plain path's buffers are
# already arrays of the width the code reads (int32 blocks, uint16 tables), used as they are.
_CAST = hasattr(memoryview, "cast")


def ptr32(buf):
    """Stand-in for viper's ptr32 cast: the buffer's memory as signed 32-bit words.

    Inside viper code MicroPython resolves `ptr32` itself and never calls this. It is called by
    the same code run as plain bytecode: under CPython (the host and the tests) it casts; on a
    MicroPython or CircuitPython without viper (the plain path, docs/firmware.md) every buffer
    handed to it is an int32 array or a view of one, returned as it is. A list (the host's
    exported constants, possibly of tracked ints) is used as it is everywhere."""
    if not _CAST or isinstance(buf, list):
        return buf
    return memoryview(buf).cast("B").cast("i")


def ptr16(buf):
    """Stand-in for viper's ptr16 cast: the buffer's memory as unsigned 16-bit words (the plain
    path's buffers are uint16 arrays already: see ptr32)."""
    if not _CAST:
        return buf
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
