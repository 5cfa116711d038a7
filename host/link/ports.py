"""Which serial port a board is on: the USB ids of the boards and bridges we know, and the one
rule `--port auto` follows (exactly one candidate, or a one-line error naming them)."""

from host.errors import UserError
from host.link.port_advice import advice

# (USB vendor id, product id or None for any) -> what is usually behind it
KNOWN = (
    ((0x2E8A, None), "Raspberry Pi RP2040/RP2350 (Pico)"),
    # CircuitPython's boards carry Adafruit's vendor id, the Pico's build too (its mpconfigboard.mk)
    ((0x239A, 0x80F4), "Raspberry Pi Pico (CircuitPython)"),
    ((0x239A, None), "Adafruit or CircuitPython board"),
    ((0xF055, 0x9800), "pyboard (MicroPython)"),
    ((0x303A, None), "Espressif native USB (ESP32-S2/S3/C3)"),
    ((0x10C4, 0xEA60), "CP210x USB-serial bridge (ESP32 DevKitC)"),
    ((0x1A86, 0x7523), "CH340 USB-serial bridge (ESP32 boards)"),
    ((0x1A86, 0x55D4), "CH9102 USB-serial bridge (ESP32 boards)"),
    ((0x0403, 0x6001), "FTDI USB-serial bridge"),
)


VIRTUAL = "sim"  # the "vendor id" list_ports gives a running virtual board (host sim)


def label(vid, pid):
    """What a port with these USB ids probably is, or None."""
    if vid == VIRTUAL:
        return "lsea-kit virtual board (host sim)"
    if vid is None:
        return None
    for (v, p), text in KNOWN:
        if v == vid and (p is None or p == pid):
            return text
    return None


def list_ports():
    """[(device, vid, pid, description)] of the machine's serial ports (pyserial), then the
    virtual boards `host sim` is running (vid VIRTUAL; host/link/running_sims.py)."""
    from serial.tools import list_ports as lp

    from host.link.running_sims import running

    usb = [(p.device, p.vid, p.pid, p.description or "") for p in sorted(lp.comports(), key=lambda p: p.device)]
    return usb + [(path, VIRTUAL, None, what) for path, what in running()]


def candidates(ports):
    """The ports (as list_ports gives them) that look like one of our boards."""
    return [p for p in ports if label(p[1], p[2]) is not None]


def choose(ports):
    """The one board port among `ports`, or UserError naming what was found."""
    found = candidates(ports)
    if len(found) == 1:
        return found[0][0]
    if not found:
        raise UserError(advice("none found", ", ".join(p[0] for p in ports) or "none"))
    raise UserError("%d boards found (%s): name one with --port" % (len(found), ", ".join(p[0] for p in found)))


def resolve(port):
    """`port` itself, or for "auto" the one board port there is."""
    return choose(list_ports()) if port == "auto" else port
