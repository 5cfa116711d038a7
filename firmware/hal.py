"""The one hardware access layer: picks the `machine` module and builds ADC, PWM, Pin and Timer.

On a board this is MicroPython's `machine`; when the board file says "simulated": true it is
`boards.sim.machine` configured with the board dict; tests may pass any machine-shaped object.
Everything above this layer only calls read_u16(), duty_u16(), value(), init() and deinit().
"""


def get_machine(board, machine=None):
    if machine is not None:
        return machine
    if board.get("simulated"):
        from boards.sim import machine as sim  # E's simulated board

        sim.configure(board, board.get("seed"))
        return sim
    import machine as hw

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


def timer(machine, board):
    return machine.Timer(board.get("timer_id", -1))


def start_timer(tim, machine, board, callback):
    kwargs = {"freq": board["loop_hz"], "mode": machine.Timer.PERIODIC, "callback": callback}
    if "timer_hard" in board:
        kwargs["hard"] = board["timer_hard"]
    tim.init(**kwargs)
