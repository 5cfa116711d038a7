"""Sampling cases (firmware/sampler.py) with ADCs that return known read_u16 sequences, run under
CPython and the real MicroPython (same pattern as app_cases.py).

Each channel is read `oversample` times per step; every read is scaled to the board's bits by
`read_u16() >> (16 - adc_bits)` (so the low bits a port fills in, e.g. rp2's code << 4 | code >> 8,
are dropped), and the reads are averaged with rounding, half up: (sum + n // 2) // n.
"""

from testkit.replay import ReplayADC, ReplayMachine


class CountingADC(ReplayADC):
    """Replays its sequence cyclically and counts every read_u16()."""

    def __init__(self, codes):
        ReplayADC.__init__(self, codes)
        self.reads = 0

    def read_u16(self):
        self.reads += 1
        return ReplayADC.read_u16(self)


class CountingMachine(ReplayMachine):
    def ADC(self, pin):
        adc = CountingADC(self.codes[pin.id])
        self.adcs[pin.id] = adc
        return adc


def case_sampling(bits, n, seq1, seq2, seq_ref, steps):
    """Sample `steps` times; return what the sampler produced and how many reads each ADC got."""
    from firmware.sampler import Sampler

    pins = {"pot1": "P1", "pot2": "P2"}
    codes = {"P1": seq1, "P2": seq2}
    if seq_ref is not None:
        pins["reference"] = "PR"
        codes["PR"] = seq_ref
    machine = CountingMachine(codes)
    s = Sampler(machine, {"adc_pins": pins, "adc_bits": bits, "oversample": n})
    s.rail_reads = 1000  # this case is about the averages; the rail check has its own cases
    out = []
    i = 0
    while i < steps:
        s.sample()
        out.append([s.raw1, s.raw2, s.raw_ref])
        i += 1
    reads = {}
    for pin, adc in machine.adcs.items():
        reads[pin] = adc.reads
    assert (s.adc_ref is None) == (seq_ref is None)
    return {"samples": out, "reads": reads}
