"""A `machine`-shaped face over CircuitPython's analogio, pwmio and digitalio, which is what
firmware/hal.py builds the ADCs, PWM outputs and pins from: CircuitPython has no `machine`.

Pins are the board file's GPIO numbers, found as `board.GP<n>` (the Pico's names). There is no
Timer: CircuitPython has no timer interrupt, so hal.start_loop paces the step from the main loop
instead (hal.PacedLoop). Values are MicroPython's: read_u16() is analogio's 16-bit value (the
RP2040's 12-bit code scaled as MicroPython's read_u16 scales it), duty_u16() sets pwmio's
duty_cycle, which has the same 0-65535 range.
"""

import analogio
import board as _board
import digitalio
import pwmio


def _pin(pin_id):
    return getattr(_board, "GP%d" % pin_id)


class Pin:
    IN = 0
    OUT = 1

    def __init__(self, pin_id, mode=None, value=None):
        self.id = pin_id
        self.io = None
        if mode == Pin.OUT:
            self.io = digitalio.DigitalInOut(_pin(pin_id))
            self.io.switch_to_output(value=bool(value))

    def value(self, v=None):
        if v is None:
            return int(self.io.value)
        self.io.value = bool(v)
        return None

    def release(self):
        """Give the pin up (a PWM output takes it next)."""
        if self.io is not None:
            self.io.deinit()
            self.io = None


class ADC:
    def __init__(self, pin):
        self._in = analogio.AnalogIn(_pin(pin.id))

    def read_u16(self):
        return self._in.value


class PWM:
    def __init__(self, pin, freq, duty_u16=0):
        pin.release()
        self._out = pwmio.PWMOut(_pin(pin.id), frequency=freq, duty_cycle=duty_u16)

    def duty_u16(self, value=None):
        if value is None:
            return self._out.duty_cycle
        self._out.duty_cycle = value
        return None

    def deinit(self):
        self._out.duty_cycle = 0
        self._out.deinit()
