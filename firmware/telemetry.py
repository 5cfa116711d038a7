"""Telemetry: the fixed-size binary record layout and the preallocated ring the control step writes.

A record is RECORD_WORDS int32 words, the fields of protocol.FIELDS in that order. The control step (a hard interrupt on a board) is the only writer; the main
loop (the link) is the only reader. Writer and reader each own one counter, so no lock is needed
and nothing is allocated on either side.

The ring's storage is an int32 array (made zeroed, with no throw-away list as large as itself)
written and read as words by viper code, and by the same code as plain bytecode where there is
no viper (CircuitPython, docs/firmware.md "The plain path"): an array indexes as words there too,
which a bytearray would not. The counters live in one int32 block, `Ring.st`;
`head`, `tail`, `dropped` and `every` are properties over it. head and tail count records
modulo 2**30, stepped without ever forming 2**30, so they stay small ints for any uptime.
"""

from firmware.portable import const, ptr32, word_property, zeros

try:
    import micropython  # @micropython.viper is resolved by MicroPython's compiler
except ImportError:  # CPython
    from firmware import portable as micropython

# the record's size: len(protocol.FIELDS) words (a constant, for the viper code)
RECORD_WORDS = const(12)
_MASK = const(0x3FFFFFFF)  # [wrap] the ring's counters wrap inside 31-bit small ints

# Ring.st
HEAD = const(0)  # records written, mod 2**30; only the writer changes it
TAIL = const(1)  # records consumed, mod 2**30; only the reader changes it
DROPPED = const(2)  # records overwritten before the reader got to them (saturates at 2**30 - 1)
EVERY = const(3)  # decimation: a record every EVERY steps (0 = recording off)
COUNTDOWN = const(4)
NREC = const(5)  # ring size in records
SLOT = const(6)  # HEAD % NREC, kept by the writer so that the step divides nothing
WORDS = const(7)


class Ring:
    """A preallocated ring of `n_records` telemetry records."""

    def __init__(self, n_records=128):
        # a power of two divides 2**30, so slot = count % n stays consistent across the counters' wrap
        if n_records < 1 or n_records & (n_records - 1) or n_records > 1 << 16:
            raise ValueError("ring size must be a power of two, 1..65536 records")
        self.n = n_records
        self.buf = zeros(n_records * RECORD_WORDS)
        self.st = zeros(WORDS)
        self.st[NREC] = n_records

    @property
    def head(self):
        return self.st[HEAD]

    @head.setter
    def head(self, v):
        self.st[HEAD] = v
        self.st[SLOT] = v % self.n

    tail = word_property(TAIL, True)
    dropped = word_property(DROPPED)
    every = word_property(EVERY, True)

    def clear(self):
        self.st[TAIL] = self.st[HEAD]
        self.st[DROPPED] = 0

    @micropython.viper
    def push(self, rec) -> bool:
        """Called once per step by the writer with the step's record (RECORD_WORDS int32s):
        kept (True) every EVERY steps, overwriting the oldest when the reader is behind."""
        s = ptr32(self.st)
        every = s[EVERY]
        if every <= 0:
            return False
        c = s[COUNTDOWN] + 1
        if c < every:
            s[COUNTDOWN] = c
            return False
        s[COUNTDOWN] = 0
        head = s[HEAD]
        src = ptr32(rec)
        dst = ptr32(self.buf)
        slot = s[SLOT]
        i = slot * RECORD_WORDS
        j = 0
        while j < RECORD_WORDS:
            dst[i + j] = src[j]
            j += 1
        slot += 1
        if head == _MASK:
            head = 0
            slot = 0  # 2**30 records: NREC divides it, so the slots start over with the count
        else:
            head += 1
        if slot == s[NREC]:
            slot = 0
        s[SLOT] = slot
        s[HEAD] = head
        return True

    def available(self):
        avail = (self.head - self.tail) & _MASK
        return avail if avail < self.n else self.n

    @micropython.viper
    def read_into(self, out) -> bool:
        """Copy the oldest unread record into `out` (RECORD_WORDS int32s, e.g. a memoryview of an
        array('i') frame slot); False if there is none."""
        s = ptr32(self.st)
        n = s[NREC]
        src = ptr32(self.buf)
        dst = ptr32(out)
        while True:
            head = s[HEAD]
            tail = s[TAIL]
            avail = (head - tail) & _MASK
            if avail == 0:
                return False
            if avail > n:
                d = s[DROPPED] + avail - n
                s[DROPPED] = d if d < _MASK else _MASK
                tail = (head - n) & _MASK
                s[TAIL] = tail
            i = (tail % n) * RECORD_WORDS
            j = 0
            while j < RECORD_WORDS:
                dst[j] = src[i + j]
                j += 1
            # The writer may have lapped us while copying (it runs in an interrupt): if the
            # slot was overwritten, the copy is torn; count it as dropped and take the next.
            if ((s[HEAD] - tail) & _MASK) > n:
                continue
            s[TAIL] = 0 if tail == _MASK else tail + 1
            return True
