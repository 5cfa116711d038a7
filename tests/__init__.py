"""The test suite, grouped by layer: firmware/ (the firmware's modules on CPython, the MicroPython
unix port and emulated chips), sim/ (the simulated actuator, and the firmware on it), fitting/,
calibration/, link/ (frames, the client, flashing, the virtual board), guided/ (the guided
calibration, the experiments, tuning) and cli/ (the commands). Shared support is the testkit
package; `pytest -q -n 3 --dist loadfile` from the repository root runs it all."""
