"""Safety: fault bits, the host-silence watchdog, and the fault texts status() shows.

The control step records faults as integers only (a bit mask plus the pot and code for a rail
fault): an interrupt cannot build strings. Text is made later, in the main loop, by describe().
Any latched fault keeps the motor off and the mode idle until App.reset().

The words the step touches live in one int32 block, `Safety.st` (indices below); `faults`,
`last`, `rail_value` and `silence` are properties over it.
"""

from firmware.portable import const, ptr32, word_property, zeros

try:
    import micropython  # @micropython.viper is resolved by MicroPython's compiler
except ImportError:  # CPython
    from firmware import portable as micropython

# [copied-constants] the bits of protocol.FAULT_NAMES (viper needs them as consts here)
FAULT_RAIL_POT1 = const(1)
FAULT_RAIL_POT2 = const(2)
FAULT_HOST_TIMEOUT = const(4)
FAULT_STEP_EXCEPTION = const(8)
FAULT_INTERRUPTED = const(16)
FAULT_RUN_EXCEPTION = const(32)
FAULT_SOFT_RESET = const(64)


# Safety.st
FAULTS = const(0)  # latched fault bits
LAST = const(1)  # the most recent fault bit
RAIL_VALUE = const(2)  # the code of a rail fault
SILENCE = const(3)  # steps since the host was last heard, in every mode, capped at SILENCE_CAP
SILENCE_LIMIT = const(4)  # steps; 0 = watchdog off
WORDS = const(5)
# The silence count stops here, so it never leaves 31 bits however long the board runs (2**29
# steps is 6 days at 1 kHz; the longest timeout is 600 000 steps).
SILENCE_CAP = const(536870912)


class Safety:
    def __init__(self, loop_hz, full_scale):
        self.loop_hz = loop_hz
        self.full_scale = full_scale
        self.st = zeros(WORDS)
        self.exc = None  # the exception object of a step/run failure (kept, not formatted)
        self.timeout_ms = 0

    faults = word_property(FAULTS)
    last = word_property(LAST)
    rail_value = word_property(RAIL_VALUE, True)
    silence = word_property(SILENCE, True)
    silence_limit = word_property(SILENCE_LIMIT)

    def set_timeout_ms(self, ms):
        self.timeout_ms = ms
        self.st[SILENCE_LIMIT] = (ms * self.loop_hz) // 1000 if ms > 0 else 0

    def heard(self):
        self.st[SILENCE] = 0

    @micropython.viper
    def tick(self) -> bool:
        """Once per step: True when the host has been silent for the watchdog time."""
        s = ptr32(self.st)
        n = s[SILENCE]
        if n < SILENCE_CAP:  # bounded however long the host is gone
            n += 1
            s[SILENCE] = n
        lim = s[SILENCE_LIMIT]
        return lim > 0 and n >= lim

    @micropython.viper
    def trip(self, bit: int):
        s = ptr32(self.st)
        s[FAULTS] = s[FAULTS] | bit
        s[LAST] = bit

    def clear(self):
        st = self.st
        st[FAULTS] = 0
        st[LAST] = 0
        st[RAIL_VALUE] = 0
        st[SILENCE] = 0
        self.exc = None

    def names(self):
        from firmware.protocol import FAULT_NAMES  # outside the step: read by status only

        return [name for bit, name in FAULT_NAMES if self.faults & bit]

    def describe(self, bit=None):
        """Human text for one fault bit (default: the last one), or None when there is none."""
        bit = self.last if bit is None else bit
        if not bit:
            return None
        if bit == FAULT_RAIL_POT1 or bit == FAULT_RAIL_POT2:
            pot = "pot1" if bit == FAULT_RAIL_POT1 else "pot2"
            side = "low" if 2 * self.rail_value < self.full_scale else "high"
            return "%s reads %d at the %s rail (wiper lifted or wire open)" % (pot, self.rail_value, side)
        if bit == FAULT_HOST_TIMEOUT:
            return "host silent for more than %d ms: motor stopped" % self.timeout_ms
        if bit == FAULT_STEP_EXCEPTION:
            return "exception in the control step: %r" % (self.exc,)
        if bit == FAULT_INTERRUPTED:
            return "run() interrupted (KeyboardInterrupt): motor stopped"
        if bit == FAULT_RUN_EXCEPTION:
            return "exception in the main loop: %r" % (self.exc,)
        if bit == FAULT_SOFT_RESET:
            return "run() ended by SystemExit (soft reset or sys.exit): motor stopped"
        return "fault 0x%x" % bit
