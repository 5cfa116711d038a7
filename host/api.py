"""lsea-kit as a library, for scripts and notebooks: open a board by port or "sim", read its
status and parameters, move the block, hold a force, stream telemetry as numpy arrays or as
records, log it to CSV while a motion runs, flash the board, fit a sweep.

    from host.api import Board

    with Board("sim", calibration="cal.json", load="gauge") as board:
        print(board.status()["mode"])
        moved = board.move(30.0)            # Settled: reached, value (mm), seconds (board time)
        run = board.record(0.5)             # {field: numpy array}, plus "t_s", board seconds

`Board` is a context manager that stops the motor when it closes, whatever ended the block.
The `host` commands status, move, force, log and params are built on it; docs/python-api.md has
a worked example (run as a test). Errors a caller can act on are host.errors.UserError, with
the same one-line messages the commands print.
"""

import contextlib
from collections import namedtuple
from dataclasses import dataclass, field

from firmware import protocol as P
from host.guided.acquire import settle
from host.link.board_client import BoardError
from host.link import stream
from host.link.connect import Connection
from host.link.board_params import read_table, set_values
from host.errors import UserError
from host.link.telemetry_log import CsvLog

Record = namedtuple("Record", P.FIELDS)
Record.__doc__ = "One telemetry record: the firmware's fields (firmware/telemetry.py), in their units (host.link.telemetry_log.UNITS)."

SETTLE_HOLD_S = 0.3  # a target counts as reached once inside the tolerance for this long (board time)


@dataclass
class Settled:
    """How a move or a force hold ended. `value` is the mean of the last 0.1 s of records, in mm
    (move) or N (force), None when no telemetry came; `seconds` are the board's own time;
    `last` is the newest record (field -> int); `faults` the board's latched faults after."""

    reached: bool
    value: float
    target: float
    seconds: float
    last: dict = field(default_factory=dict)
    faults: list = field(default_factory=list)
    stroke_end: str = None  # not reached, and the block is at the soft stroke limit of this end ("0.5 mm", "59.5 mm")
    cause: str = None  # not reached: why, as far as the board's last record tells (why_not_settled)

    def as_dict(self):
        """For JSON: value and seconds rounded to what they resolve (0.1 um or 0.1 mN; 1 ms)."""
        return {"reached": self.reached, "value": None if self.value is None else round(self.value, 4),
                "target": self.target, "seconds": round(self.seconds, 3),
                "faults": self.faults, "stroke_end": self.stroke_end, "cause": self.cause, "last": self.last}


DUTY_LIMIT_FRACTION = 0.95  # a duty this close to out_limit is the loop asking for more than it may


def why_not_settled(last, faults, stroke_end, out_limit):
    """Why a motion did not settle, in words, from the board's newest record `last` (field ->
    int), its latched `faults`, the stroke end the block sits at (None: not at one) and the
    out_limit parameter in force: a fault, a stroke end, the duty at its limit against a load,
    else the loop still short of the tolerance (friction, or a tolerance tighter than it holds)."""
    if faults:
        return "a fault stopped the motor: %s (host reset clears it)" % ", ".join(faults)
    if stroke_end:
        return "the block is at the soft stroke limit near %s (the target lies beyond what it may reach)" % stroke_end
    duty = int(last.get("duty", 0)) if last else 0
    if out_limit and abs(duty) >= DUTY_LIMIT_FRACTION * out_limit:
        return ("the motor is at its duty limit (%d of out_limit %d) against %.2f N: the load holds it, or the "
                "target asks more than the motor gives" % (duty, out_limit, int(last.get("force_mN", 0)) / 1000.0))
    return ("the loop stayed outside the tolerance with no fault, limit or saturation (duty %d): friction holding "
            "the block, or a tolerance tighter than the loop holds (host tune shows its response)" % duty)


def _load(load):
    if load is None or isinstance(load, dict):
        return load
    from host.link.bench_load import parse_load

    try:
        return parse_load(load)
    except ValueError as exc:  # the message says what is accepted
        raise UserError(str(exc)) from None


class Board:
    """A board on `port`: a serial device, "auto" (the one board `host ports` finds) or "sim" (a
    virtual board started for the life of this object, with `board`, `calibration` and `load`,
    e.g. "gauge@45"; on boards/sim.json it starts with the simulated actuator's shipped
    calibration unless `calibration` is given or `uncalibrated`). The firmware's version and protocol are checked on opening;
    `require_calibration` also refuses a board without a usable calibration.

    Closing stops the motor (mode idle). `stop_on_exit=False` leaves a motion running when the
    block ends normally (the firmware's host timeout stops it a second later); an exception still
    stops it."""

    def __init__(self, port="auto", board=None, calibration=None, load=None, require_calibration=False,
                 stop_on_exit=True, uf2=None, uncalibrated=False):
        self.stop_on_exit = stop_on_exit
        self._connection = Connection(port, board, calibration, _load(load), uf2=uf2, ready=not uncalibrated,
                                      require_calibration=require_calibration).open()
        self.client = self._connection.client

    @property
    def port(self):
        """The serial device (the pty of a virtual board)."""
        return self.client.port

    @property
    def virtual(self):
        """The virtual board behind port "sim" (VirtualBoard: its files, its load) or "sim:rp2040"
        (EmulatedPico: its rig, its actuator's state), else None."""
        return self._connection.virtual

    def close(self, stop=True):
        if self.client is None:
            return
        try:
            if stop:
                self.client.call("stop")
        except Exception:
            pass  # a board that vanished cannot be stopped from here; its host timeout will
        finally:
            self._connection.close()
            self.client = None

    def __enter__(self):
        return self

    def __exit__(self, exc_type, *exc):
        self.close(stop=self.stop_on_exit or exc_type is not None)

    # -- state -------------------------------------------------------------------------
    def status(self):
        """Every field the firmware reports (dict): version, board, calibration CRC, mode, faults,
        loop timing ... (`host status` shows them)."""
        return self.client.call("status")

    def stop(self):
        """Motor off, mode idle."""
        self.client.call("stop")

    def params(self):
        """{name: host.link.board_params.Param} from the board's own table: value, default, limits, unit."""
        return read_table(self.client)

    def set_params(self, values=None, save=False, **named):
        """Set parameters ({name: int} and/or name=int), each checked against the board's limits
        before any is set; save=True keeps the values in force on the board (loaded at boot).
        Returns (the table after, the board's answer to save or None)."""
        return set_values(self.client, dict(values or {}, **named), save=save)

    # -- motions -----------------------------------------------------------------------
    def _needs_calibration(self, what):
        status = self.client.status_info or {}
        if status.get("calibration_crc") is None:
            raise UserError("%s needs a calibrated board: this one has no usable calibration (%s)"
                            % (what, status.get("calibration_error")))

    def _settle(self, mode, target, field_name, tolerance, timeout_s, hold, progress):
        last = {}
        try:
            ok, value, seconds = settle(self._connection.link, mode, target, field_name, tolerance, timeout_s, SETTLE_HOLD_S,
                                        progress=progress, last=last)
        finally:
            if not hold:
                self.client.call("stop")
        faults = self.client.call("status").get("faults") or []
        end = self.stroke_end(last["d2_um"]) if last and not ok else None
        cause = None if ok else why_not_settled(last, faults, end, self.client.call("get", "out_limit"))
        return ok, value, seconds, last, faults, end, cause

    def move(self, to_mm, tolerance_mm=0.2, timeout_s=15.0, hold=False, progress=None):
        """Closed-loop position move of the output block to `to_mm` (inside the soft stroke limits,
        stroke_limits_um(): 0.5-59.5 mm on a 0-60 mm actuator), until D2 stays within
        `tolerance_mm` for 0.3 s of board time or `timeout_s` of it passed; motor off after unless
        `hold`. `progress(mm, seconds)` is called about 5 times a second of board time."""
        self._needs_calibration("a move")
        lo, hi = self.stroke_limits_um()
        if not lo <= round(to_mm * 1000) <= hi:
            raise UserError("%.3f mm is outside the soft stroke limits in force, %.3f..%.3f mm (the "
                            "stroke_min_um/stroke_max_um parameters, kept stop_margin_um inside the calibrated end "
                            "stops; host status shows both)" % (to_mm, lo / 1000, hi / 1000))
        shown = (lambda um, s: progress(um / 1000, s)) if progress else None
        ok, value, seconds, last, faults, end, cause = self._settle("position", int(round(to_mm * 1000)), "d2_um",
                                                                    int(round(tolerance_mm * 1000)), timeout_s, hold, shown)
        return Settled(ok, None if value is None else value / 1000, to_mm, seconds, last, faults, end, cause)

    def force(self, newtons, tolerance_n=0.1, timeout_s=15.0, hold=False, progress=None):
        """Closed-loop force (spring deformation) to `newtons` (negative pulls toward 0 mm), until
        F0(d) stays within `tolerance_n` for 0.3 s of board time or `timeout_s` passed; motor off
        after unless `hold`. The block needs something to push against (a load)."""
        self._needs_calibration("force control")
        shown = (lambda mn, s: progress(mn / 1000, s)) if progress else None
        ok, value, seconds, last, faults, end, cause = self._settle("force", int(round(newtons * 1000)), "force_mN",
                                                                    int(round(tolerance_n * 1000)), timeout_s, hold, shown)
        return Settled(ok, None if value is None else value / 1000, newtons, seconds, last, faults, end, cause)

    def stroke_limits_um(self):
        """[low, high] um: the soft stroke limits on D2 in force (the parameters, kept off the
        calibrated end stops), as the firmware reports them."""
        return self.client.call("status").get("stroke_um") or [-P.POSITION_LIMIT_UM, P.POSITION_LIMIT_UM]

    def stroke_end(self, d2_um):
        """The soft stroke limit D2 is at ("0.5 mm", "59.5 mm" on a 0-60 mm actuator): inside its slow
        zone at that end; else None."""
        try:
            lo, hi = self.stroke_limits_um()
            zone = self.client.call("get", "slow_zone_um")
        except BoardError:  # a firmware without soft stroke limits
            return None
        for limit, near in ((lo, d2_um <= lo + zone), (hi, d2_um >= hi - zone)):
            if near:
                return "%g mm" % (limit / 1000.0)
        return None

    # -- telemetry ---------------------------------------------------------------------
    def stream(self, seconds=None, rate=1000):
        """Telemetry records (Record) for `seconds` of the board's time (None: until the loop
        that reads them stops), at `rate` Hz; heartbeats keep the host timeout away meanwhile."""
        for rows in self.stream_arrays(seconds, rate):
            for row in rows.tolist():
                yield Record(*row)

    def stream_arrays(self, seconds=None, rate=1000):
        """As stream(), a numpy int32 array (records x P.FIELDS) per frame as it arrives."""
        with stream.closing(stream.records(self._connection.link, seconds, rate)) as arrays:
            for rows, _board_s in arrays:
                yield rows

    def record(self, seconds, rate=1000):
        """`seconds` of the board's time at `rate` Hz as {field: numpy int64 array} (the shape
        host.link.telemetry_log.load gives a CSV), plus "t_s": each record's board time in seconds."""
        arrays = stream.Arrays()
        self._connection.stream(seconds, rate, [arrays])
        return arrays.run()

    @contextlib.contextmanager
    def log(self, path, rate=1000, on_rows=None, stop=None):
        """Within the block, telemetry at `rate` Hz goes to CSV `path` (and RUN.meta.json beside
        it) while move()/force()/record() run over the same connection; `on_rows(records)` sees
        each frame's records as they arrive. Yields the host.link.stream.Tee (its .summary counts
        samples and lost frames; .pump() only records). `stop`: see Tee."""
        with CsvLog(path, self.client.call("status"), rate) as csv_log:
            sinks = [csv_log] if on_rows is None else [csv_log, on_rows]
            with self._connection.tee(rate, sinks, stop) as tee:
                yield tee

    # -- flashing ------------------------------------------------------------------------
    def flash(self, calibration=None, board=None):
        """Install the firmware, the board file and (optionally) a calibration on this board, as
        `host flash` does, and reconnect. Returns the firmware's status after."""
        try:
            return self._connection.reflash(board, calibration)
        finally:
            self.client = self._connection.client


@dataclass
class SweepFit:
    """A calibration curve fitted to a sweep: `result` (host.fitting.fit_result.FitResult: call it on raw
    readings, .rms, .max_abs, .model, .order), the `sweep` it was fitted to, its `noise_floor`
    and `hysteresis` (reference units, None when unknown) and, for model "auto", why that model."""

    result: object
    sweep: object
    noise_floor: float
    hysteresis: float
    reason: str = None

    def plot(self, path, unit="mm"):
        """The fit figure (sweep, curve, residuals) as a PNG at `path`."""
        from host.fitting.plots import plot_fit

        return plot_fit(path, self.sweep.x, self.sweep.y, self.result, unit=unit, noise=self.noise_floor,
                        direction=self.sweep.direction)


def fit_sweep(path, model="auto", order=None):
    """Fit one potentiometer's sweep CSV (columns raw, reference[, direction]) as `host fit` does:
    model "auto" (the cheapest firmware model within 0.5 % of the lowest cross-validated error), "bcm", "pwl", ..."""
    from host.fitting.pot_fit import fit_sweep as fit  # the one copy of `host fit`'s fitting
    from host.fitting.sweep import load_sweep

    sweep = load_sweep(path)
    result, floors, reason = fit(sweep, model, order)
    return SweepFit(result, sweep, floors["noise_floor"], floors["hysteresis"], reason)
