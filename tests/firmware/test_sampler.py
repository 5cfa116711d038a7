"""Sampling with known ADC sequences (tests/firmware/sampler_cases.py), on CPython and MicroPython:
oversample mean with rounding, the shift to the board's bits, the reference channel."""


import pytest

from testkit.interpreters import same


def both(call):
    return same("tests.firmware.sampler_cases", call)


def rp2_u16(code):
    """What rp2's read_u16 returns for a 12-bit code (ports/rp2/machine_adc.c)."""
    return code << 4 | code >> 8


def test_mean_of_four_reads_rounds_half_up_at_12_bits():
    # per step, pot1 reads 4 codes; their exact means: 100.0, 100.25, 100.5, 100.75, 4094.5
    codes1 = [100, 100, 100, 100, 100, 100, 100, 101, 100, 100, 101, 101, 100, 101, 101, 101,
              4094, 4094, 4095, 4095]
    # pot2 with noise in the 4 bits below the 12 (any value 0..15 must vanish in the shift)
    codes2 = [2000, 2001, 2002, 2003] * 5
    low = [0, 15, 7, 8] * 5
    seq1 = [rp2_u16(c) for c in codes1]
    seq2 = [(c << 4) | b for c, b in zip(codes2, low)]
    seq_ref = [rp2_u16(c) for c in [0, 1, 1, 1, 3000, 3000, 3001, 3002] + [5] * 12]
    out = both("case_sampling(12, 4, %r, %r, %r, 5)" % (seq1, seq2, seq_ref))
    assert [s[0] for s in out["samples"]] == [100, 100, 101, 101, 4095]
    # 2000..2003: mean 2001.5 -> 2002 every step, whatever the low bits
    assert [s[1] for s in out["samples"]] == [2002] * 5
    # reference: mean 0.75 -> 1, 3000.75 -> 3001, then 5
    assert [s[2] for s in out["samples"]] == [1, 3001, 5, 5, 5]
    assert out["reads"] == {"P1": 20, "P2": 20, "PR": 20}  # exactly oversample reads per step


@pytest.mark.parametrize("bits", [8, 10, 12, 16])
def test_every_code_survives_the_shift_at_each_adc_width(bits):
    """One read per sample: the code a port left-aligns into read_u16 comes back exactly, with
    every possible pattern in the bits below it."""
    shift = 16 - bits
    codes = [0, 1, 2, (1 << bits) // 3, (1 << bits) - 2, (1 << bits) - 1]
    seq = [(c << shift) | ((1 << shift) - 1 if shift else 0) for c in codes]
    seq2 = [c << shift for c in codes]
    out = both("case_sampling(%d, 1, %r, %r, None, %d)" % (bits, seq, seq2, len(codes)))
    assert [s[0] for s in out["samples"]] == codes
    assert [s[1] for s in out["samples"]] == codes
    assert [s[2] for s in out["samples"]] == [0] * len(codes)  # no reference channel: 0
    assert out["reads"] == {"P1": len(codes), "P2": len(codes)}


def test_odd_oversample_rounds_to_nearest():
    """oversample 3 at 10 bits: means 1.67 -> 2, 1.33 -> 1, 0.33 -> 0, 1023 -> 1023."""
    codes = [1, 2, 2, 1, 1, 2, 0, 0, 1, 1023, 1023, 1023]
    seq = [c << 6 for c in codes]
    out = both("case_sampling(10, 3, %r, %r, %r, 4)" % (seq, seq, seq))
    assert out["samples"] == [[2, 2, 2], [1, 1, 1], [0, 0, 0], [1023, 1023, 1023]]
    assert out["reads"] == {"P1": 12, "P2": 12, "PR": 12}


def test_the_rounding_matches_an_exact_reference():
    """64 reads per sample over a ramp (the most the board file allows): the firmware's
    (sum + n//2) // n equals floor(mean + 1/2) computed exactly."""
    from fractions import Fraction
    import math

    n = 64
    codes = [(37 * i * i + 11 * i) % 4096 for i in range(n * 6)]
    seq = [c << 4 for c in codes]
    out = both("case_sampling(12, %d, %r, %r, None, 6)" % (n, seq, seq[::-1]))
    for step in range(6):
        chunk = codes[step * n:(step + 1) * n]
        chunk2 = codes[::-1][step * n:(step + 1) * n]
        assert out["samples"][step][0] == math.floor(Fraction(sum(chunk), n) + Fraction(1, 2))
        assert out["samples"][step][1] == math.floor(Fraction(sum(chunk2), n) + Fraction(1, 2))
