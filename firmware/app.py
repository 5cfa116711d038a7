"""The firmware application: boot (board file, calibration), the command surface, the main loop.

The link (firmware/link.py) calls these methods; the timer calls Controller.step. Every path
out of run() (return, exception, KeyboardInterrupt, soft reset's SystemExit) leaves the motor
off, and then records why run() ended: status()["last_exit"], and a one-line record
(`exit_record`, firmware/records.py: "last_exit.txt" on a board) that the next boot reads back, so
the cause of a Ctrl-C or a soft reset is readable afterwards. Without a usable calibration, raw readings and open loop still
work; closed-loop modes are refused with the reason, and status() shows it.
"""

import sys
import time

from firmware import hal
from firmware.controller import EF, FORCE, IDLE, OPEN_LOOP, PARKED, POSITION, SP_FRAC, Controller
from firmware.measurement import STROKE_CLAMP_UM, Measurement, board_problem
from firmware.motor import Motor
from firmware.portable import release
from firmware.pi_control import DUTY_MAX
from firmware.param_table import ParamTable, index as param_index
from firmware.protocol import MODES, PROTOCOL_VERSION, VERSION, interface_hash
from firmware.safety import FAULT_HOST_TIMEOUT, FAULT_INTERRUPTED, FAULT_RUN_EXCEPTION, FAULT_SOFT_RESET, Safety
from firmware.sampler import Sampler
from firmware.telemetry import Ring

FORCE_TARGET_MAX_MN = 200000  # 200 N, far beyond the actuator; keeps poly() inputs bounded
EXIT_TEXT_MAX = 200
# The main loop's passes (link, host watchdog) are at most this far apart when there is nothing
# to do. A pass costs about 0.2 ms of an RP2040; run at every interrupt (the step's, USB's), as
# the emulated Pico showed (docs/emulated-pico.md), passes kept its CPU about 70 % busy at rest.
PASS_MS = 8
# What the exit file says while run() runs: if the next boot still finds it, run() never got to
# its finally (power loss, hard reset, watchdog, crash).
EXIT_RUNNING = "none recorded: run() was still running (power loss, hard reset, watchdog or crash)"

try:
    import micropython

    micropython.alloc_emergency_exception_buf(100)  # tracebacks from the timer IRQ
except (ImportError, AttributeError):
    pass


def _rest(idle, waiting):
    """Between two passes of the main loop: idle (a board sleeps until its next interrupt) until
    PASS_MS have passed, or sooner when `waiting()` (the link's) says there is input; without
    `waiting`, one idle(). At 1 kHz a pass finds up to 8 records to send, half a frame."""
    if waiting is None:
        idle()
        return
    deadline = _ticks_add(_ticks_ms(), PASS_MS)
    idle()
    while not waiting() and _ticks_diff(deadline, _ticks_ms()) > 0:
        idle()


try:
    _ticks_ms = time.ticks_ms
    _ticks_add = time.ticks_add
    _ticks_diff = time.ticks_diff
except AttributeError:  # CPython

    def _ticks_ms():
        return int(time.monotonic() * 1000)

    def _ticks_add(a, b):
        return a + b

    def _ticks_diff(a, b):
        return a - b


def _read_exit(record):
    """The exit cause the previous run() left in `record`, or None (none, nothing readable)."""
    if record is None:
        return None
    try:
        text = record.read(EXIT_TEXT_MAX)
    except (OSError, ValueError):  # undecodable bytes, a damaged record
        return None
    return (text or "").strip() or None


def _interpreter():
    """("micropython 1.29.0", mpy version word or None): what runs the firmware, for bringup's
    check that the .mpy files match it (sys.implementation._mpy: version, sub-version, arch)."""
    impl = sys.implementation
    v = impl.version
    return "%s %d.%d.%d" % (impl.name, v[0], v[1], v[2]), getattr(impl, "_mpy", None)


def _load_board(path):
    """The checked board file (firmware.board_config, imported for the boot only: see release)."""
    from firmware.board_config import load_board

    return load_board(path)


def _load_calibration(path):
    """(calibration, None) or (None, reason). firmware.calibration is imported for this only and
    let go after the boot (release): the Calibration it returns is data."""
    if path is None:
        return None, "no calibration file configured"
    from firmware.calibration import CalibrationError, load_calibration

    try:
        return load_calibration(path), None
    except CalibrationError as exc:
        return None, "calibration %s unusable: %s" % (path, exc)
    except OSError:
        return None, "calibration file %s not found" % path
    except (ValueError, KeyError, TypeError) as exc:  # corrupt content the loader did not catch
        return None, "calibration %s corrupt: %r" % (path, exc)
    except MemoryError:  # e.g. a deeply nested or huge file: boot without it, motor off
        return None, "calibration %s too large for this board's memory" % path
    except Exception as exc:  # anything else (RecursionError, ...): the board must still boot
        return None, "calibration %s unreadable: %r" % (path, exc)


class App:
    def __init__(self, board_path, calibration_path, machine=None, ring_records=128, exit_record=None, params_record=None):
        """`exit_record`, `params_record`: where the exit cause and the saved parameters are kept
        across boots (firmware/records.py; hal.record gives a board's), None for nowhere."""
        self.board = _load_board(board_path)
        self.machine = hal.get_machine(self.board, machine)
        # The motor first, so that whatever fails later at boot, the bridge is already off.
        self.motor = Motor(self.machine, self.board)
        self.sampler = Sampler(self.machine, self.board)
        self.telemetry = Ring(ring_records)
        self.safety = Safety(self.board["loop_hz"], (1 << self.board["adc_bits"]) - 1)
        self.ctrl = Controller(self.sampler, None, self.motor, self.telemetry, self.safety, self.board["loop_hz"])
        cal, why = _load_calibration(calibration_path)
        self.calibration = None
        self.force_range = None
        self.calibration_error = why
        if cal is not None:
            self.set_calibration(cal)
        self.step = self.ctrl.step  # the bound method made once, before any heap lock / IRQ
        # the parameters in force (the saved ones, else this board's defaults) and where each came from
        self.params_table = ParamTable(self.ctrl.p, self.board, params_record)
        self.ctrl.apply_params()
        self.params_restored = None
        self._timeout_restored = False  # the parameters came back for the host_timeout latched now
        self._timer = None
        self.timer_kind = hal.timer_kind(self.board)  # what the board file asks; start() says what it got
        self._quit = False
        self.exit_record = exit_record
        self.last_exit = _read_exit(exit_record)  # why the previous run() ended (this boot's or the last)
        self.interpreter, self.mpy = _interpreter()
        self.interface = interface_hash()  # once, at boot: the table's text is a kilobyte of heap
        # the modules only the boot needed: on a board their code goes back to the heap
        release("firmware.board_config")
        release("firmware.calibration")

    def set_calibration(self, cal):
        """Use a loaded Calibration (or None for raw readings only). Goes idle first."""
        self.stop()
        self.ctrl.meas = None
        self.calibration = None
        self.ctrl.end_stops = None
        self.force_range = None
        self.ctrl.apply_params()
        if cal is None:
            self.calibration_error = "no calibration loaded"
            return
        try:
            why = board_problem(cal, self.board)  # before any curve is evaluated
            if why is not None:
                self.calibration_error = why
                return
            meas = Measurement(cal, loop_hz=self.board["loop_hz"])
        except Exception as exc:  # MemoryError, a curve that falls, anything: boot on without it
            self.calibration_error = "calibration unusable: %s" % (exc,)
            return
        meas.update(self.sampler.raw1, self.sampler.raw2)
        self.calibration = cal
        self.calibration_error = None
        self.ctrl.meas = meas
        self.ctrl.end_stops = getattr(cal, "stroke", None)
        self.force_range = getattr(cal, "force_range", None)  # [low_mN, high_mN] the calibration held, or None
        self.ctrl.apply_params()

    # --- commands (each one also counts as hearing from the host) ---------------------------
    def status(self):
        sf = self.safety
        cal = self.calibration
        return {
            "version": VERSION,
            "board": self.board["name"],
            "calibration_crc": cal.crc if cal is not None else None,
            "calibration_error": self.calibration_error,
            "mode": MODES[self.ctrl.mode],
            "faults": sf.names(),
            "last_fault": sf.describe(),
            "target": self.ctrl.target,
            "duty": self.ctrl.duty,
            "steps": self.ctrl.steps,
            "step_us_max": self.ctrl.step_us_max,
            "overruns": self.ctrl.overruns,
            "period_us": self.ctrl.period_us,
            "stroke_um": self.ctrl.stroke_limits,
            "end_stops_um": None if self.ctrl.end_stops is None else list(self.ctrl.end_stops),
            "force_range_mN": None if self.force_range is None else list(self.force_range),
            "params_changed": self.params_table.changed_names(),
            "params_saved": self.params_table.saved(),
            "params_file_error": self.params_table.file_error,
            "params_restored": self.params_restored,
            "params_temporary": self.params_table.temporary_names(),
            "timer": self.timer_kind,
            "interpreter": self.interpreter,
            "mpy": self.mpy,
            "last_exit": self.last_exit,
            "protocol": PROTOCOL_VERSION,
            "interface": self.interface,
        }

    def heartbeat(self):
        self.safety.heard()

    def stop(self):
        self.ctrl.mode = IDLE
        self.motor.off()
        self.ctrl.duty = 0
        self.safety.heard()

    def reset(self):
        """Clear latched faults and go idle (the motor stays off until a new set_mode)."""
        self.stop()
        self.sampler.clear_rail()
        self.safety.clear()
        self.ctrl.pi.reset()

    def _why_not(self, mode):
        if self.safety.faults:
            return "fault latched (%s): reset first" % self.safety.describe()
        if mode in (POSITION, FORCE):
            m = self.ctrl.meas
            if m is None:
                return "%s mode needs a calibration: %s" % (MODES[mode], self.calibration_error)
            return m.missing_for(MODES[mode])
        return None

    def set_mode(self, name):
        if name not in MODES:
            raise ValueError("unknown mode %r (one of %s)" % (name, ", ".join(MODES)))
        mode = MODES.index(name)
        self.safety.heard()
        if mode == IDLE:
            self.stop()
            return
        why = self._why_not(mode)
        if why:
            raise ValueError(why)
        c = self.ctrl
        c.mode = IDLE  # the step keeps the motor off while the new mode is set up
        c.pi.reset()
        if mode == POSITION:
            c.target = c.meas.d2  # hold where it is until told otherwise
            c.st[EF] = 0
            c.st[PARKED] = 0
        elif mode == FORCE:
            c.set_force_target(0)
            c.fdir = 0
            c.defl_sp = c.meas.defl  # the ramp starts from the deformation the spring has now
            c.st[SP_FRAC] = 0
        else:
            c.target = 0
        c.mode = mode

    def set_target(self, value):
        value = int(value)
        self.safety.heard()
        c = self.ctrl
        if c.mode == OPEN_LOOP or c.mode == IDLE:
            if c.mode == OPEN_LOOP and not -DUTY_MAX <= value <= DUTY_MAX:
                raise ValueError("open-loop duty must be within +-%d" % DUTY_MAX)
        elif c.mode == POSITION:
            if not -STROKE_CLAMP_UM <= value <= STROKE_CLAMP_UM:
                raise ValueError("position target must be within +-%d um" % STROKE_CLAMP_UM)
            c.st[PARKED] = 0  # a new target is a new move, however small (one store: IRQ-safe)
        elif c.mode == FORCE:
            if not -FORCE_TARGET_MAX_MN <= value <= FORCE_TARGET_MAX_MN:
                raise ValueError("force target must be within +-%d mN" % FORCE_TARGET_MAX_MN)
            held = self.force_range  # beyond it F0 is the end of its fit: a target there would be a silent miss
            if held is not None and not held[0] <= value <= held[1]:
                raise ValueError("force target %d mN is beyond what the force calibration held (%d..%d mN): "
                                 "the spring and motor were not shown to hold it" % (value, held[0], held[1]))
            c.set_force_target(value)
        c.target = value

    def params(self):
        """The parameter table with the values in force: [name, value, default, min, max, unit]
        (the default is this board's: the table's, or from its board file's stroke)."""
        return self.params_table.rows()

    def save_params(self):
        """Keep the parameters in force on the board (loaded at the next boot). Idle only: a
        flash write may hold up the control step."""
        if self.ctrl.mode != IDLE:
            raise ValueError("stop first: parameters are saved only while idle")
        self.safety.heard()
        return self.params_table.save()

    def get_param(self, name):
        self.safety.heard()
        return self.ctrl.p[param_index(name)]

    def set_param(self, name, value, temporary=False):
        """Set a parameter; `temporary`: for the host command that sets it only, so it goes back
        to the value it had before when the host goes silent (watch_host)."""
        self.params_table.set(name, value, temporary)
        self.safety.heard()
        self.ctrl.apply_params()

    def watch_host(self):
        """Main loop, every pass: what the host changed comes back by itself when it goes silent.

        When the watchdog has stopped a motion (host_timeout latched), every parameter goes back
        to its boot value, once per trip (a host that sets one afterwards keeps it): a host killed
        mid-sweep must not leave the stroke limits open for the next one. When the host has been
        silent for host_timeout_ms with the motor off, the temporary values (set_param's
        `temporary`) go back to what they were before: a host killed between two sweeps, or
        while its person reads a dial gauge, leaves nothing open either. Values set for good
        stay while the board is idle, so a host tuning by hand keeps its settings."""
        sf = self.safety
        table = self.params_table
        if sf.faults & FAULT_HOST_TIMEOUT:
            if self._timeout_restored:
                return False
            self._timeout_restored = True
            changed = table.restore(to_boot=True)
            what = "back to boot values"
        else:
            self._timeout_restored = False
            limit = sf.silence_limit
            if not table.n_temporary or not limit or sf.silence < limit:
                return False
            changed = table.restore(to_boot=False)
            what = "(temporary) back to their values before"
        if not changed:
            return False
        self.ctrl.apply_params()
        self.params_restored = "host silent: %s %s" % (", ".join(changed), what)
        return True

    def stream(self, state, hz=1000):
        """The `stream` command: telemetry "on" at `hz` or "off"; returns {"hz": the rate}."""
        if state == "off":
            hz = 0
        elif hz <= 0:
            raise ValueError("rate must be > 0 Hz")
        self.set_stream(hz)
        return {"hz": hz}

    def set_stream(self, hz):
        hz = int(hz)
        loop_hz = self.board["loop_hz"]
        if hz < 0 or hz > loop_hz:
            raise ValueError("stream rate must be 0..%d Hz" % loop_hz)
        self.safety.heard()
        self.telemetry.every = loop_hz // hz if hz else 0
        self.telemetry.clear()

    # --- the loop ---------------------------------------------------------------------------
    def start(self):
        """Start the control timer (run() does this)."""
        if self._timer is None:
            self.ctrl.timer_started()
            self._timer, self.timer_kind = hal.start_loop(self.machine, self.board, self.step)

    def shutdown(self):
        """Stop the timer, then the motor. Safe to call any number of times."""
        self.ctrl.mode = IDLE
        try:
            if self._timer is not None:
                self._timer.deinit()
        finally:
            self._timer = None
            self.motor.off()
            self.ctrl.duty = 0

    def quit(self):
        """Ask run() to return after the current iteration (e.g. from a link command)."""
        self._quit = True

    def run(self, link=None):
        """Main loop: the timer runs the step, this loop serves the link. Motor off on exit,
        then the cause recorded (status()["last_exit"] and the exit file)."""
        idle = getattr(self.machine, "idle", None)
        self._quit = False
        cause = None
        try:
            self._write_exit(EXIT_RUNNING)
            self.start()
            waiting = getattr(link, "waiting", None)
            paced = getattr(self._timer, "run_due", None)  # no timer interrupt: this loop runs the step
            if paced is not None:
                idle = None  # nothing wakes a sleeping board but the step's own time
            while not self._quit:
                if paced is not None:
                    paced()
                if link is not None:
                    link.poll()
                self.watch_host()
                if idle is not None:
                    _rest(idle, waiting)
        except BaseException as exc:  # KeyboardInterrupt and SystemExit too
            try:
                self.shutdown()  # the motor off before anything else
            finally:
                cause = self._exit_cause(exc)
            raise
        finally:
            try:
                self.shutdown()
            finally:
                self._record_exit(cause)

    def _exit_cause(self, exc):
        """Latch the fault for an exception that ended run(); the cause text for the record."""
        if isinstance(exc, KeyboardInterrupt):
            self.safety.trip(FAULT_INTERRUPTED)
            return "interrupted: KeyboardInterrupt (Ctrl-C)"
        if isinstance(exc, SystemExit):
            self.safety.trip(FAULT_SOFT_RESET)
            return "soft_reset: SystemExit (soft reset or sys.exit)"
        self.safety.exc = exc
        self.safety.trip(FAULT_RUN_EXCEPTION)
        try:
            return "run_exception: %r" % (exc,)
        except Exception:  # e.g. MemoryError: the kind of exit is still worth recording
            return "run_exception"

    def _record_exit(self, cause):
        """Remember why run() ended (after the motor is off): in status() and in the exit file,
        where the next boot finds it. A record that cannot be made must not hide the exit."""
        try:
            if cause is None:
                cause = "returned: run() ended normally (quit)"
            self.last_exit = ("%s after %d steps, motor off" % (cause, self.ctrl.steps))[:EXIT_TEXT_MAX]
        except Exception:  # MemoryError while formatting: keep the bare cause
            self.last_exit = cause
        self._write_exit(self.last_exit)

    def _write_exit(self, text):
        if self.exit_record is None or text is None:
            return
        try:
            self.exit_record.write(text)
        except Exception:  # a full or read-only filesystem: the status still has it
            pass
