"""What to tell a person whose board's serial port would not open, in their platform's words.

The same trouble reads differently on each platform: Linux names a board's port /dev/ttyACM0
(/dev/ttyUSB0 behind a USB-serial bridge) and lets only the dialout group open it; macOS names it
/dev/cu.usbmodem*; Windows names it COMn, shows it in the Device Manager and answers "Access is
denied" when another program has the port open, as it lets one program at a time open a COM port.
Every piece of such advice is phrased here, by `advice`, for a `platform` given as a sys.platform
value (default: this machine's), so that each platform's words can be checked on any machine.
"""

import sys

# what each platform calls a board's port, for examples in messages and help
EXAMPLE_PORT = {"win32": "COM3", "darwin": "/dev/cu.usbmodem1101", "linux": "/dev/ttyACM0"}

# programs that hold a board's port open, the usual reason it is busy
OTHER_PROGRAMS = "Thonny, mpremote, a serial monitor, another host command"


def _family(platform):
    """"win32", "darwin" or "linux" (every other POSIX system names and guards ports as Linux does)."""
    platform = platform or sys.platform
    return platform if platform in ("win32", "darwin") else "linux"


def example_port(platform=None):
    return EXAMPLE_PORT[_family(platform)]


def problem_of(error_text):
    """What pyserial's message for a port that did not open says: "missing", "denied", "busy", or
    None for anything else. The words, not errno: pyserial on Windows gives no errno."""
    text = error_text.lower()
    if "no such file" in text or "filenotfounderror" in text or "cannot find the file" in text:
        return "missing"
    if "permission" in text or "access is denied" in text:
        return "denied"
    if "busy" in text or "lock" in text or "resource temporarily unavailable" in text:  # flock by another client
        return "busy"
    return None


def advice(problem, port, platform=None):
    """The one-line message for `problem` ("missing", "denied", "busy", "none found": no board
    among the machine's ports, `port` then names the ports seen, or "no ports": the machine has
    none, `port` unused) on `port`, in `platform`'s words."""
    family = _family(platform)
    if problem == "denied" and family == "win32":
        problem = "busy"  # Windows denies a port that another program has open, not a user
    if problem == "missing":
        if family == "win32":  # no virtual board on Windows itself (it needs a pseudo-terminal)
            return ("serial port %s not found (is the board plugged in? the Device Manager shows its COM port under "
                    "Ports (COM & LPT); `host ports` lists them)" % port)
        return ("serial port %s not found (is the board plugged in? `host ports` lists the ports, e.g. %s; try `host "
                "sim` for a virtual board)" % (port, "/dev/ttyACM0 or /dev/ttyUSB0" if family == "linux"
                                                else "/dev/cu.usbmodem*"))
    if problem == "busy":
        if family == "win32":
            return ("serial port %s is busy: close the other program using the port (%s); Windows lets one program at "
                    "a time open a COM port" % (port, OTHER_PROGRAMS))
        return ("serial port %s is busy: close the other program using it (%s); `%s %s` names it"
                % (port, OTHER_PROGRAMS, "fuser" if family == "linux" else "lsof", port))
    if problem == "denied":
        if family == "linux":
            return ("no permission to open serial port %s: add yourself to the dialout group (`sudo usermod -aG dialout "
                    "$USER`, then log out and in again)" % port)
        return "no permission to open serial port %s (`ls -l %s` shows who may)" % (port, port)
    if problem == "none found":
        if family == "win32":
            return ("no board found (serial ports: %s): plug it in, or name it with --port (e.g. COM3: the Device "
                    "Manager shows it under Ports (COM & LPT))" % port)
        return ("no board found (serial ports: %s): plug it in, or name it with --port (e.g. %s); for a virtual board "
                "start `host sim` in another terminal, or use --port sim (one for this command only)"
                % (port, example_port(family)))
    if problem == "no ports":
        if family == "win32":
            return "no serial ports (plug the board in: the Device Manager shows its COM port under Ports (COM & LPT))"
        return "no serial ports (plug the board in; or start `host sim` for a virtual board, or use --port sim)"
    raise ValueError("no advice for %r" % problem)


def open_failure(port, error_text, platform=None):
    """The one-line message for a serial port that would not open, from pyserial's `error_text`."""
    problem = problem_of(error_text)
    if problem is None:
        return "cannot open serial port %s: %s" % (port, error_text)
    return advice(problem, port, platform)
