"""The firmware modules under CPython and the real MicroPython unix port (the same cases on both,
*_cases.py), compiled by mpy-cross, and on emulated Cortex-M0/M3 chips."""
