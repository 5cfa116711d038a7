"""The wires between a board and the simulated actuator: which sensor an ADC pin carries, and the
voltage the H-bridge puts across the motor from the levels of its input pins.

The board file says how the firmware expects the actuator to be wired (`adc_pins`, `motor_pins`,
`driver`, `supply_volts`); the actuator's `wiring` says where a bench's wires really go when they
differ, as on a first bench (host calibrate bringup finds it):
  "adc": {"pot1": "pot2", ...}    the pin meant for pot 1 carries the block's pot (pots swapped)
  "pot_reversed": ["pot1"]        pot 1's track ends swapped: its reading falls as the nut goes out
  "motor_reversed": true          the motor leads swapped: positive voltage drives toward 0 mm
A harness is built once, from the board file the bench was wired for: flashing a corrected board
file changes what the firmware expects, never where the wires go.

Used by the MicroPython unix port's simulated `machine` (boards/sim/machine.py, pins are labels)
and by the emulated Pico's bench (host/link/emulated_pico/bench.py, pins are GPIO numbers).
"""

from boards.sim.actuator import CHANNELS


class Harness:
    def __init__(self, board, actuator):
        wiring = actuator.get("wiring") or {}
        swap = wiring.get("adc") or {}
        reversed_pots = wiring.get("pot_reversed") or ()
        self.adc = {}  # pin -> (actuator channel, the code's complement is read)
        for label, pin in board["adc_pins"].items():
            channel = swap.get(label, label)
            if channel not in CHANNELS:
                raise ValueError("pin %r carries no sensor of the actuator (%r)" % (pin, channel))
            self.adc[pin] = (channel, channel in reversed_pots)
        self.supply = float(board["supply_volts"]) * (-1.0 if wiring.get("motor_reversed") else 1.0)
        self.driver = board["driver"]
        if self.driver not in ("two_pwm", "pwm_dir"):
            raise ValueError("unknown driver %r" % self.driver)
        self.motor_pins = board["motor_pins"]

    def channel(self, pin):
        """(actuator channel, reversed) on ADC pin `pin`; ValueError when it carries none."""
        try:
            return self.adc[pin]
        except KeyError:
            raise ValueError("pin %r is not wired to a sensor of the actuator" % (pin,))

    def motor_volts(self, level):
        """Volts across the motor; `level(pin)` is a bridge input's mean level, 0 (low) to 1 (high):
        a PWM pin's duty, a plain output pin's 0 or 1.
          two_pwm (DRV8833 IN1/IN2): V = supply * (IN1 - IN2)
          pwm_dir (TB6612 PWM + DIR): V = +-supply * PWM, + when DIR is high"""
        pins = self.motor_pins
        if self.driver == "two_pwm":
            return self.supply * (level(pins["in1"]) - level(pins["in2"]))
        sign = 1.0 if level(pins["dir"]) >= 0.5 else -1.0
        return sign * self.supply * level(pins["pwm"])
