"""Repeatable randomness for the simulated world: an xorshift32 generator and a normal-noise table.

MicroPython's `random` differs from CPython's, so the simulation carries its own generator. Every
step is integer arithmetic (no libm), so a seed gives bit-identical noise on both interpreters.
Reading the noise is allocation-free on MicroPython (small ints only): ADC reads may happen
inside a firmware step that is proven under micropython.heap_lock().
"""

import math
from array import array

MASK32 = 0xFFFFFFFF
TABLE_BITS = 12
TABLE_SIZE = 1 << TABLE_BITS
# Noise table values are a unit normal in 1/256 LSB (Q8): standard deviation exactly ~256.
Q8 = 256


def xorshift32(x):
    """One step of Marsaglia's xorshift32 (13, 17, 5); x must be a non-zero 32-bit int."""
    x ^= (x << 13) & MASK32
    x ^= x >> 17
    x ^= (x << 5) & MASK32
    return x


def seed_state(seed):
    """A non-zero 32-bit generator state from any int seed (zero would stick at zero)."""
    x = (int(seed) * 2654435761 + 0x9E3779B9) & MASK32
    if x == 0:
        x = 0x6D2B79F5
    for _ in range(8):  # decorrelate nearby seeds
        x = xorshift32(x)
    return x


class Rng:
    """xorshift32 stream with uniform floats and sum-of-uniforms normals (integer core)."""

    def __init__(self, seed):
        self.state = seed_state(seed)

    def next_u32(self):
        self.state = xorshift32(self.state)
        return self.state

    def uniform(self):
        """A float in [0, 1) with 32 random bits (exact on both interpreters)."""
        return self.next_u32() / 4294967296.0

    def normal_q16(self):
        """Approximately N(0, 1) scaled by 2**16: the Irwin-Hall sum of 12 uniform 16-bit values.

        Twelve U(0,1) have variance 1, so sum - 6 is a unit normal cut at +-6 sigma; integer only.
        """
        s = 0
        i = 0
        while i < 6:
            u = self.next_u32()
            s += (u & 0xFFFF) + (u >> 16)
            i += 1
        return s - 6 * 65536


def normal_table(rng):
    """array('i') of TABLE_SIZE values, a unit normal in Q8, rescaled so the table's own standard
    deviation is 256 to within rounding (the ADC noise then has the configured sigma, not
    sigma +- 2 %). One 16 KiB block, filled in place: light on a small MicroPython heap."""
    t = array("i", bytes(4 * TABLE_SIZE))
    total = 0
    for i in range(TABLE_SIZE):
        v = rng.normal_q16()
        t[i] = v
        total += v
    mean = total // TABLE_SIZE
    ss = 0
    for v in t:
        ss += (v - mean) * (v - mean)
    # sqrt is correctly rounded in IEEE 754 on both interpreters, so this scale is bit-identical.
    scale = Q8 * math.sqrt(TABLE_SIZE / ss)
    for i in range(TABLE_SIZE):
        v = t[i] - mean
        t[i] = int(v * scale + (0.5 if v >= 0 else -0.5))
    return t
