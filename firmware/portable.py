"""What lets one firmware source run under MicroPython and, for tests, under CPython.

MicroPython provides `const` and the `native`/`viper` code emitters; CPython gets identity
stand-ins so the same module imports unchanged.
"""

try:
    from micropython import const, native, viper  # noqa: F401
except ImportError:  # CPython

    def const(value):
        return value

    def native(func):
        return func

    def viper(func):
        return func
