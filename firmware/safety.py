"""Safety: fault bits, the host-silence watchdog, and the fault texts status() shows.

The control step records faults as integers only (a bit mask plus the pot and code for a rail
fault): an interrupt cannot build strings. Text is made later, in the main loop, by describe().
Any latched fault keeps the motor off and the mode idle until App.reset().
"""

from firmware.portable import const

FAULT_RAIL_POT1 = const(1)
FAULT_RAIL_POT2 = const(2)
FAULT_HOST_TIMEOUT = const(4)
FAULT_STEP_EXCEPTION = const(8)
FAULT_INTERRUPTED = const(16)
FAULT_RUN_EXCEPTION = const(32)
FAULT_SOFT_RESET = const(64)

FAULT_NAMES = (
    (FAULT_RAIL_POT1, "rail_pot1"),
    (FAULT_RAIL_POT2, "rail_pot2"),
    (FAULT_HOST_TIMEOUT, "host_timeout"),
    (FAULT_STEP_EXCEPTION, "step_exception"),
    (FAULT_INTERRUPTED, "interrupted"),
    (FAULT_RUN_EXCEPTION, "run_exception"),
    (FAULT_SOFT_RESET, "soft_reset"),
)


class Safety:
    def __init__(self, loop_hz, full_scale):
        self.loop_hz = loop_hz
        self.full_scale = full_scale
        self.faults = 0
        self.last = 0  # the most recent fault bit
        self.rail_value = 0
        self.exc = None  # the exception object of a step/run failure (kept, not formatted)
        self.silence = 0  # steps since the host was last heard
        self.silence_limit = 0  # steps; 0 = watchdog off
        self.timeout_ms = 0

    def set_timeout_ms(self, ms):
        self.timeout_ms = ms
        self.silence_limit = (ms * self.loop_hz) // 1000 if ms > 0 else 0

    def heard(self):
        self.silence = 0

    def tick(self):
        """Once per step while the motor may run: True when the host has been silent too long."""
        self.silence += 1
        if self.silence_limit and self.silence >= self.silence_limit:
            self.silence = self.silence_limit  # stays bounded however long the host is gone
            return True
        return False

    def trip(self, bit):
        self.faults |= bit
        self.last = bit

    def clear(self):
        self.faults = 0
        self.last = 0
        self.rail_value = 0
        self.exc = None
        self.silence = 0

    def names(self):
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
