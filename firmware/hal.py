"""The one hardware access layer: picks the `machine` module and builds ADC, PWM, Pin and Timer.

The `machine` is MicroPython's on a board. The virtual board installs the simulated actuator's
as `machine` before the firmware boots (host/link/virtual_board.py), so the firmware never knows
it is simulated; tests may pass any machine-shaped object. Everything above this layer only
calls read_u16(), duty_u16(), value(), init() and deinit().
"""


def get_machine(board, machine=None):
    """`machine` when given, else the `machine` module; on CircuitPython, which has none, the
    machine-shaped face over its analogio, pwmio and digitalio (firmware/circuitpython_hw.py)."""
    if machine is not None:
        return machine
    try:
        import machine as hw
    except ImportError:
        from firmware import circuitpython_hw as hw

    return hw


def adc(machine, pin_id):
    """ADC on a pin. ESP32 pins get the 11 dB attenuation (full 0-3.3 V range, see board notes)."""
    a = machine.ADC(machine.Pin(pin_id))
    atten = getattr(machine.ADC, "ATTN_11DB", None)
    if atten is not None and hasattr(a, "atten"):
        a.atten(atten)
    return a


class _PybTimerPWM:
    """machine.PWM shape over a pyb.Timer channel (the stm32 port has no machine.PWM)."""

    def __init__(self, pin_id, freq, timer_id, channel):
        import pyb

        self._tim = pyb.Timer(timer_id, freq=freq)
        self._ch = self._tim.channel(channel, pyb.Timer.PWM, pin=pyb.Pin(pin_id), pulse_width=0)
        self._period = self._tim.period() + 1
        self._duty = 0

    def duty_u16(self, value=None):
        if value is None:
            return self._duty
        self._duty = value
        # (value >> 2) <= 16383 and period <= 65536 keep the product below 2**30 (no big int
        # in the interrupt); the 2 dropped bits are 1/16384 of full scale.
        self._ch.pulse_width(((value >> 2) * self._period) >> 14)
        return None

    def deinit(self):
        self._ch.pulse_width(0)


def pwm(machine, pin_id, freq, pyb_timer=None):
    """A PWM output starting at duty 0. `pyb_timer` = [timer, channel] selects the pyb path."""
    if pyb_timer is not None:
        return _PybTimerPWM(pin_id, freq, pyb_timer[0], pyb_timer[1])
    p = machine.PWM(machine.Pin(pin_id, machine.Pin.OUT), freq=freq, duty_u16=0)
    p.duty_u16(0)
    return p


def out_pin(machine, pin_id):
    return machine.Pin(pin_id, machine.Pin.OUT, value=0)


def timer_kind(board):
    """How the board file's loop timer runs the step: "hard" (in the timer interrupt) or "soft"
    (scheduled to run between bytecodes of the main loop, so garbage collection delays it)."""
    if board.get("timer_api") == "pyb" or board.get("timer_hard"):
        return "hard"
    return "soft"


_MASK = 0x3FFFFFFF  # portable.ticks_us wraps at 2**30


class PacedLoop:
    """The loop timer of a runtime with no timer interrupt (CircuitPython): the main loop calls
    run_due() on every pass, and it calls the step when its time has come, every 1e6 / hz us,
    measured from when the previous one was due (a late step does not shift the ones after it;
    a loop more than a whole period behind starts counting again from now, and the step counts
    the late start as an overrun).

    The clock: CircuitPython's supervisor.ticks_ms when the period is whole milliseconds. It
    allocates nothing, where time.monotonic_ns (the only finer clock there) makes two long ints
    a call, and the main loop asks at every pass, about 15 times a period: about 1 KB of garbage
    a step, a 12 ms collection every fifth of a second (docs/circuitpython.md). A step then starts
    within a pass (about 0.23 ms) of its millisecond. Elsewhere portable.ticks_us, in us."""

    def __init__(self, hz, callback):
        period_us = 1000000 // hz
        try:
            from supervisor import ticks_ms  # wraps at 2**29

            if period_us % 1000:
                raise ImportError
            self._ticks, self.period, self._mask = ticks_ms, period_us // 1000, (1 << 29) - 1
        except ImportError:
            from firmware.portable import ticks_us

            self._ticks, self.period, self._mask = ticks_us, period_us, _MASK
        self._callback = callback
        self._next = (self._ticks() + self.period) & self._mask
        self.on = True

    def run_due(self):
        """Run the step if it is due; True when it ran."""
        if not self.on:
            return False
        mask = self._mask
        now = self._ticks()
        if (now - self._next) & mask > mask >> 1:  # next is still ahead (differences mod the wrap)
            return False
        self._callback(self)
        nxt = (self._next + self.period) & mask
        if (now - nxt) & mask <= mask >> 1:  # more than a period behind
            nxt = (now + self.period) & mask
        self._next = nxt
        return True

    def deinit(self):
        self.on = False


def start_loop(machine, board, callback):
    """Start the periodic loop timer at board["loop_hz"] calling `callback(timer)`.

    Returns (timer, kind): the object to deinit() and "hard", "soft" or "paced" (what it really
    is). A `machine` without a Timer (CircuitPython's face) gets a PacedLoop, which the main loop
    runs (App.run calls its run_due()).
    - "timer_api": "pyb" (the stm32 port): pyb.Timer(timer_id, freq=, callback=); pyb.Timer
      callbacks run in hard IRQ context on every stm32 release.
    - otherwise machine.Timer(timer_id).init(freq=, mode=PERIODIC, callback=), with hard=True
      when the board file says "timer_hard": true. A port that refuses it (rp2 before 1.26 has
      no hard= and raises TypeError; esp32 raises ValueError "hard Timers are not implemented")
      gets the same timer without hard=, which is soft: reported as such, never silent.
    """
    hz = board["loop_hz"]
    if not hasattr(machine, "Timer") and board.get("timer_api") != "pyb":
        return PacedLoop(hz, callback), "paced"
    if board.get("timer_api") == "pyb":
        import pyb

        return pyb.Timer(board["timer_id"], freq=hz, callback=callback), "hard"
    tim = machine.Timer(board.get("timer_id", -1))
    if board.get("timer_hard"):
        try:
            tim.init(freq=hz, mode=machine.Timer.PERIODIC, callback=callback, hard=True)
            return tim, "hard"
        except (TypeError, ValueError):
            pass
    tim.init(freq=hz, mode=machine.Timer.PERIODIC, callback=callback)
    return tim, "soft"


def console_stream():
    """(stdin, write) for the link: (None, None) for sys.stdin and sys.stdout (MicroPython);
    on CircuitPython, whose sys.stdin and sys.stdout are text, its USB console as the binary
    serial usb_cdc.console, read without waiting (timeout 0)."""
    try:
        import usb_cdc
    except ImportError:
        return None, None
    console = usb_cdc.console
    if console is None:
        return None, None
    console.timeout = 0
    return console, console.write


# Where each record lives in CircuitPython's 4 KiB microcontroller.nvm: (offset, bytes)
NVM_SLOTS = {"last_exit.txt": (0, 512), "params.txt": (512, 2048)}


def record(path):
    """The record the firmware keeps under `path` across boots (firmware/records.py), None for
    None: the file on MicroPython; on CircuitPython, whose drive is read-only to code, its slot of
    microcontroller.nvm (named "nvm:" + path)."""
    from firmware import records

    if path is None:
        return None
    try:
        from microcontroller import nvm  # CircuitPython's; no such module on MicroPython
    except ImportError:
        nvm = None
    if nvm is not None and path in NVM_SLOTS:
        offset, size = NVM_SLOTS[path]
        return records.NvmRecord(nvm, offset, size, "nvm:" + path)
    return records.FileRecord(path)
