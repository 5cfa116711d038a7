"""Telemetry: the fixed-size binary record layout and the preallocated ring the control step writes.

This module is the one source of truth for the record layout: every field is an int32, in the
order of FIELDS. The control step (a hard interrupt on a board) is the only writer; the main
loop (the link) is the only reader. Writer and reader each own one counter, so no lock is needed
and nothing is allocated on either side.
"""

from array import array

from firmware.portable import const

FIELDS = (
    "t_us",  # loop time since start, us (step count x period, wraps at 2**30)
    "raw1",  # pot 1 code, board-native bits, oversampled mean
    "raw2",  # pot 2 code
    "raw_ref",  # reference channel code (0 when the board has none)
    "d1_um",  # nut position D1* (after the Df correction), um
    "d2_um",  # output block position D2, um
    "defl_um",  # spring deformation d = D1* - D2, um
    "force_mN",  # F0(d), mN
    "target",  # the mode's target: duty, um or mN
    "duty",  # signed duty sent to the bridge, [-DUTY_MAX, DUTY_MAX]
    "mode",  # mode number (controller.MODE_NAMES)
    "faults",  # fault bit mask (safety.FAULT_NAMES)
)
RECORD_WORDS = const(12)
RECORD_BYTES = const(48)
_MASK = const(0x3FFFFFFF)  # counters wrap inside the 31-bit small-int range of 32-bit boards


class Ring:
    """A preallocated ring of `n_records` telemetry records.

    `every` is the decimation: a record is kept every `every` steps (0 = recording off).
    `dropped` counts records overwritten before the reader got to them.
    """

    def __init__(self, n_records=128):
        if n_records < 1:
            raise ValueError("ring needs at least one record")
        self.n = n_records
        self.buf = array("i", [0] * (n_records * RECORD_WORDS))
        self.head = 0  # records written (masked); only the writer changes it
        self.tail = 0  # records consumed (masked); only the reader changes it
        self.dropped = 0
        self.every = 0
        self._countdown = 0

    def clear(self):
        self.tail = self.head
        self.dropped = 0

    def due(self):
        """Called once per step by the writer: True when this step's record should be kept."""
        if self.every <= 0:
            return False
        self._countdown += 1
        if self._countdown < self.every:
            return False
        self._countdown = 0
        return True

    def write_record(self, t_us, raw1, raw2, raw_ref, d1, d2, defl, force, target, duty, mode, faults):
        buf = self.buf
        i = (self.head % self.n) * RECORD_WORDS
        buf[i] = t_us
        buf[i + 1] = raw1
        buf[i + 2] = raw2
        buf[i + 3] = raw_ref
        buf[i + 4] = d1
        buf[i + 5] = d2
        buf[i + 6] = defl
        buf[i + 7] = force
        buf[i + 8] = target
        buf[i + 9] = duty
        buf[i + 10] = mode
        buf[i + 11] = faults
        self.head = (self.head + 1) & _MASK

    def available(self):
        avail = (self.head - self.tail) & _MASK
        return avail if avail < self.n else self.n

    def read_into(self, dst):
        """Copy the oldest unread record into `dst` (array('i') of RECORD_WORDS); False if empty."""
        while True:
            head = self.head
            avail = (head - self.tail) & _MASK
            if avail == 0:
                return False
            if avail > self.n:
                self.dropped += avail - self.n
                self.tail = (head - self.n) & _MASK
            tail = self.tail
            i = (tail % self.n) * RECORD_WORDS
            j = 0
            buf = self.buf
            while j < RECORD_WORDS:
                dst[j] = buf[i + j]
                j += 1
            # The writer may have lapped us while copying (it runs in an interrupt): if the
            # slot was overwritten, the copy is torn; count it as dropped and take the next.
            if ((self.head - tail) & _MASK) > self.n:
                continue
            self.tail = (tail + 1) & _MASK
            return True
