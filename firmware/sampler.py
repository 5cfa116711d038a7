"""Sampling: oversampled ADC reads of pot 1, pot 2 and the reference, plus the rail check.

Each channel is read `oversample` times per step with read_u16() and scaled to the board's native
bits (read_u16 is left-aligned to 16 bits on every port). A wiper that lifts off its track reads
as a rail (0 or full scale); `rail_reads` consecutive raw reads at a rail on one pot is a fault
that names the pot and the value. Reads are counted individually (not per averaged sample) so
that with oversample >= rail_reads the fault trips in the same step the reads go bad.

What the step reads and writes lives in one int32 block, `Sampler.st` (indices below), so the
viper step touches it with single loads and stores; the attributes people and tests use
(raw1, rail, rail_reads, ...) are properties over the same block.
"""

from firmware import hal
from firmware.portable import const, ptr32, word_property, zeros

try:
    import micropython  # @micropython.viper is resolved by MicroPython's compiler
except ImportError:  # CPython
    from firmware import portable as micropython

NO_RAIL = const(0)
RAIL_POT1 = const(1)
RAIL_POT2 = const(2)

# Sampler.st
RAW1 = const(0)  # pot 1 code, native bits, mean of the step's reads (rounded half up)
RAW2 = const(1)
RAW_REF = const(2)  # reference channel (0 when the board has none)
RAIL = const(3)  # which pot tripped (latched until clear_rail)
RAIL_VALUE = const(4)  # the code it read
RUN1 = const(5)  # consecutive rail reads so far, per pot, capped at NEED (bounded for any uptime)
RUN2 = const(6)
N = const(7)  # reads per channel per step (oversample)
SHIFT = const(8)  # 16 - adc_bits
LO = const(9)  # a read <= LO or >= HI is at a rail
HI = const(10)
NEED = const(11)  # rail_reads
HAS_REF = const(12)
FLIP1 = const(13)  # the pot's mean is XORed with this: full scale for a pot in "pot_invert", else 0
FLIP2 = const(14)
WORDS = const(15)


class Sampler:
    def __init__(self, machine, board):
        pins = board["adc_pins"]
        self.bits = board["adc_bits"]
        self.shift = 16 - self.bits
        self.full = (1 << self.bits) - 1
        self.oversample = board.get("oversample", 4)
        if not 1 <= self.oversample <= 64:
            raise ValueError("oversample must be 1..64")
        st = zeros(WORDS)
        self.st = st
        self.adc1 = hal.adc(machine, pins["pot1"])
        self.adc2 = hal.adc(machine, pins["pot2"])
        ref = pins.get("reference")
        self.adc_ref = hal.adc(machine, ref) if ref is not None else None
        st[N] = self.oversample
        st[SHIFT] = self.shift
        # "pot_invert": a pot whose reading falls as its part moves toward 60 mm is read as
        # full - code (code ^ full for codes within 0..full), so every later stage sees it rise
        invert = board.get("pot_invert") or ()
        st[FLIP1] = self.full if "pot1" in invert else 0
        st[FLIP2] = self.full if "pot2" in invert else 0
        self._margin = 0
        self.rail_reads = 4
        self.rail_margin = 0

    # --- the ADCs: each read_u16 is bound once here (binding allocates; the step then calls the
    # bound method, ~150 instructions a read cheaper than looking the method up each time) -----
    @property
    def adc1(self):
        return self._adc1

    @adc1.setter
    def adc1(self, adc):
        self._adc1 = adc
        self._read1 = adc.read_u16

    @property
    def adc2(self):
        return self._adc2

    @adc2.setter
    def adc2(self, adc):
        self._adc2 = adc
        self._read2 = adc.read_u16

    @property
    def adc_ref(self):
        return self._adc_ref

    @adc_ref.setter
    def adc_ref(self, adc):
        self._adc_ref = adc
        self._read_ref = None if adc is None else adc.read_u16
        self.st[HAS_REF] = 0 if adc is None else 1

    # --- the block's fields, for people and tests -----------------------------------------------
    raw1 = word_property(RAW1)
    raw2 = word_property(RAW2)
    raw_ref = word_property(RAW_REF)
    rail = word_property(RAIL)
    rail_value = word_property(RAIL_VALUE)
    rail_reads = word_property(NEED, True)  # consecutive reads at a rail that make a fault

    @property
    def rail_margin(self):
        """Codes from a rail that still count as "at the rail"."""
        return self._margin

    @rail_margin.setter
    def rail_margin(self, m):
        self._margin = m
        self.st[LO] = m
        self.st[HI] = self.full - m

    def clear_rail(self):
        st = self.st
        st[RAIL] = NO_RAIL
        st[RAIL_VALUE] = 0
        st[RUN1] = 0
        st[RUN2] = 0

    @micropython.viper
    def sample(self):
        """One step's sample: sets RAW1, RAW2, RAW_REF (native bits) and may latch a rail fault.
        Allocation-free: the bound read methods were made at boot."""
        s = ptr32(self.st)
        r1 = self._read1
        r2 = self._read2
        n = s[N]
        shift = s[SHIFT]
        lo = s[LO]
        hi = s[HI]
        need = s[NEED]
        s1 = 0
        s2 = 0
        run1 = s[RUN1]
        run2 = s[RUN2]
        i = 0
        while i < n:
            c1 = int(r1()) >> shift
            c2 = int(r2()) >> shift
            s1 += c1  # <= 64 * 65535 < 2**22
            s2 += c2
            if c1 <= lo or c1 >= hi:
                run1 += 1
                if run1 >= need and s[RAIL] == NO_RAIL:
                    s[RAIL] = RAIL_POT1
                    s[RAIL_VALUE] = c1
            else:
                run1 = 0
            if c2 <= lo or c2 >= hi:
                run2 += 1
                if run2 >= need and s[RAIL] == NO_RAIL:
                    s[RAIL] = RAIL_POT2
                    s[RAIL_VALUE] = c2
            else:
                run2 = 0
            i += 1
        s[RUN1] = run1 if run1 < need else need
        s[RUN2] = run2 if run2 < need else need
        s[RAW1] = ((s1 + (n >> 1)) // n) ^ s[FLIP1]
        s[RAW2] = ((s2 + (n >> 1)) // n) ^ s[FLIP2]
        if s[HAS_REF]:
            rr = self._read_ref
            t = 0
            i = 0
            while i < n:
                t += int(rr()) >> shift
                i += 1
            s[RAW_REF] = (t + (n >> 1)) // n
