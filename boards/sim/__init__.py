"""The simulated actuator board: a physical model of the LSEA (actuator.py) behind a module
shaped like MicroPython's `machine` (machine.py), portable to MicroPython and CPython."""
