"""The emulated Raspberry Pi Pico: rp2040js running the Pico's MicroPython, the simulated actuator on its pins.

board.py (EmulatedPico: start it, its serial device, the rig), bench.py (the process that runs the
chip in lockstep with the actuator), node.py (Node and the pinned rp2040js), pico.mjs (the chip).
"""
