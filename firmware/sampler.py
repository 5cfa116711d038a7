"""Sampling: oversampled ADC reads of pot 1, pot 2 and the reference, plus the rail check.

Each channel is read `oversample` times per step with read_u16() and scaled to the board's native
bits (read_u16 is left-aligned to 16 bits on every port). A wiper that lifts off its track reads
as a rail (0 or full scale); `rail_reads` consecutive raw reads at a rail on one pot is a fault
that names the pot and the value. Reads are counted individually (not per averaged sample) so
that with oversample >= rail_reads the fault trips in the same step the reads go bad.
"""

from firmware import hal
from firmware.portable import const

NO_RAIL = const(0)
RAIL_POT1 = const(1)
RAIL_POT2 = const(2)


class Sampler:
    def __init__(self, machine, board):
        pins = board["adc_pins"]
        self.bits = board["adc_bits"]
        self.shift = 16 - self.bits
        self.full = (1 << self.bits) - 1
        self.oversample = board.get("oversample", 4)
        if not 1 <= self.oversample <= 64:
            raise ValueError("oversample must be 1..64")
        self.adc1 = hal.adc(machine, pins["pot1"])
        self.adc2 = hal.adc(machine, pins["pot2"])
        ref = pins.get("reference")
        self.adc_ref = hal.adc(machine, ref) if ref is not None else None
        self.raw1 = 0
        self.raw2 = 0
        self.raw_ref = 0
        self.rail_margin = 0  # codes from a rail that still count as "at the rail"
        self.rail_reads = 4  # consecutive reads at a rail that make a fault
        self._run1 = 0
        self._run2 = 0
        self.rail = NO_RAIL  # which pot tripped (latched until clear_rail)
        self.rail_value = 0  # the code it read

    def clear_rail(self):
        self.rail = NO_RAIL
        self.rail_value = 0
        self._run1 = 0
        self._run2 = 0

    def sample(self):
        """One step's sample: sets raw1, raw2, raw_ref (native bits) and may latch a rail fault."""
        n = self.oversample
        shift = self.shift
        lo = self.rail_margin
        hi = self.full - self.rail_margin
        need = self.rail_reads
        a1 = self.adc1
        a2 = self.adc2
        s1 = 0
        s2 = 0
        run1 = self._run1
        run2 = self._run2
        i = 0
        while i < n:
            c1 = a1.read_u16() >> shift
            c2 = a2.read_u16() >> shift
            s1 += c1  # <= 64 * 65535 < 2**22
            s2 += c2
            if c1 <= lo or c1 >= hi:
                run1 += 1
                if run1 >= need and self.rail == NO_RAIL:
                    self.rail = RAIL_POT1
                    self.rail_value = c1
            else:
                run1 = 0
            if c2 <= lo or c2 >= hi:
                run2 += 1
                if run2 >= need and self.rail == NO_RAIL:
                    self.rail = RAIL_POT2
                    self.rail_value = c2
            else:
                run2 = 0
            i += 1
        self._run1 = run1 if run1 < need else need
        self._run2 = run2 if run2 < need else need
        self.raw1 = (s1 + (n >> 1)) // n
        self.raw2 = (s2 + (n >> 1)) // n
        ar = self.adc_ref
        if ar is not None:
            s = 0
            i = 0
            while i < n:
                s += ar.read_u16() >> shift
                i += 1
            self.raw_ref = (s + (n >> 1)) // n
