"""Test support, shared by tests/ and bench/ (an installed package: no sys.path edits).

- interpreters: run a case (a function in a module both interpreters import) or a program under
  CPython and the real MicroPython unix port, and compare the results bit for bit (exact);
- replay: a machine-shaped stand-in that replays ADC codes recorded from the simulated actuator,
  and an App booted on it with a calibration file (runs under both interpreters);
- model: calibration files of the simulated actuator written by the real calibration-file code,
  and ADC recordings of it (CPython);
- processes: `host` commands as child processes that a test can interrupt.
"""
