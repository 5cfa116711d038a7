"""Record board telemetry to CSV: one row per record, columns = firmware.protocol.FIELDS.

`Recording(board, path, rate)` streams from a BoardClient while a motion runs through it (one
connection for both), or alone with `pump()`; `record(board, path, seconds, rate)` does the
latter. Rows are written as they arrive (so a Ctrl-C or a lost port still leaves a complete file
up to the last frame), heartbeats keep the host timeout away, and a `LogSummary` says what came
(samples, rate, lost frames counted by sequence number, board drops).
Beside the CSV (a plain table any tool reads) it writes RUN.meta.json: the board, firmware and
protocol version, calibration CRC, loop period, stream rate, the date, each column's unit, and
the code tables of the `mode` and `faults` columns.
"""

import csv
import datetime
import json
import time
from dataclasses import dataclass
from pathlib import Path

from firmware.protocol import FAULT_NAMES, FIELD_UNITS, FIELDS, MODES
from host.link import stream
from host.link.board_time import NO_DATA_S, BoardTime

# What each column is, for people (a new telemetry field must say it here: tests check); its unit
# is the interface table's (firmware/protocol.py FIELD_UNITS)
MEANING = {
    "t_us": "since the firmware started, wraps at 2**30",
    "raw1": "pot 1 (board-native bits)",
    "raw2": "pot 2",
    "raw_ref": "reference input (0 without one)",
    "d1_um": "nut position D1* (Df corrected)",
    "d2_um": "output block position D2",
    "defl_um": "spring deformation D1* - D2",
    "force_mN": "F0(d)",
    "target": "the mode's target: duty (open_loop), um (position), mN (force)",
    "duty": "signed, 10000 = 100 %",
    "mode": "see modes",
    "faults": "bit mask: see faults",
}
UNITS = {name: "%s: %s" % (unit, MEANING[name]) for name, unit in zip(FIELDS, FIELD_UNITS)}

# What the firmware computes from the calibration; all 0 in records from a board without one.
CALIBRATED_FIELDS = ("d1_um", "d2_um", "defl_um", "force_mN")


@dataclass
class LogSummary:
    samples: int = 0
    seconds: float = 0.0  # of the board's time the records span
    lost_frames: int = 0
    board_dropped: int = 0
    crc_errors: int = 0
    skipped_bytes: int = 0
    interrupted: bool = False

    @property
    def rate(self):
        return self.samples / self.seconds if self.seconds > 0 else 0.0

    def line(self):
        return "%d samples in %.2f s (%.1f/s), lost frames %d, board ring drops %d, CRC errors %d%s" % (
            self.samples, self.seconds, self.rate, self.lost_frames, self.board_dropped, self.crc_errors,
            " (interrupted)" if self.interrupted else "")


def metadata_path(path):
    """RUN.meta.json beside RUN.csv."""
    path = Path(path)
    return path.with_name(path.stem + ".meta.json")


def metadata(status, rate):
    """What a log's numbers need to be read later: from the board's status at the start."""
    from host import __version__ as host_version

    crc = status.get("calibration_crc")
    period = status.get("period_us")
    return {
        "date": datetime.datetime.now(datetime.timezone.utc).replace(microsecond=0).isoformat(),
        "board": status.get("board"), "firmware": status.get("version"), "protocol": status.get("protocol"),
        "interpreter": status.get("interpreter"),
        "calibration_crc": None if crc is None else "%08x" % (crc & 0xFFFFFFFF),
        "calibration_error": status.get("calibration_error"),
        "loop_period_us": period, "loop_hz": round(1e6 / period, 3) if period else None, "stream_hz": rate,
        "host": host_version,
        "columns": {name: UNITS[name] for name in FIELDS},
        "modes": {str(i): name for i, name in enumerate(MODES)},
        "faults": {str(bit): name for bit, name in FAULT_NAMES},
    }


class Recording:
    """Telemetry streamed at `rate` Hz into CSV `path` while other code drives the board through
    this object: one connection serves a motion and its log.

    It stands in for the BoardClient where a motion streams (host.guided.acquire.settle,
    api.Board.stream_arrays): call, request, heartbeat_if_due, start_stream, frames and
    stop_stream, nothing else. The stream stays on at the recording's rate whatever a caller's
    start_stream asks, and every frame handed out by frames() is first written to the CSV and
    given to `on_rows(records)`.
    `stop` (a threading.Event) set from another thread makes the next frames() raise
    KeyboardInterrupt, so whatever drives the board ends through its usual clean-up (motor off).
    Rows are written as they arrive, so a Ctrl-C or a lost port still leaves a complete file."""

    def __init__(self, client, path, rate=1000, on_rows=None, stop=None):
        self.client = client
        self.path = path
        self.rate = rate
        self.on_rows = on_rows
        self.stop = stop
        self.summary = LogSummary()
        self._file = self._writer = None

    @property
    def port(self):
        return self.client.port

    def call(self, name, *args, **kw):
        return self.client.call(name, *args, **kw)

    def request(self, name, *args, **kw):
        return self.client.request(name, *args, **kw)

    def heartbeat_if_due(self):
        return self.client.heartbeat_if_due()

    def __enter__(self):
        meta = metadata(self.client.call("status"), self.rate)
        metadata_path(self.path).write_text(json.dumps(meta, indent=1) + "\n")
        decoder = self.client.decoder
        self._counts0 = decoder.lost_frames, decoder.crc_errors, decoder.skipped_bytes
        self._file = open(self.path, "w", newline="")
        self._writer = csv.writer(self._file)
        self._writer.writerow(FIELDS)
        self.client.start_stream(self.rate)
        self._clock = BoardTime()  # the summary's seconds: the board's, as `host log --seconds` counts
        return self

    def frames(self, timeout=0.1):
        if self.stop is not None and self.stop.is_set():
            raise KeyboardInterrupt
        frames = self.client.frames(timeout=timeout)
        for frame in frames:
            self._write(frame)
        return frames

    def start_stream(self, hz):
        """The stream is on already, at the recording's rate: what came so far goes to the file,
        and the caller sees only frames from now on."""
        self.frames(timeout=0)
        return {"hz": self.rate}

    def stop_stream(self):
        return {"hz": self.rate}  # stays on until the recording ends

    def _write(self, frame):
        rows = frame.records()
        try:
            self._writer.writerows(rows.tolist())
        except OSError as exc:  # a full disk shows here, at a buffer's flush: say which file
            raise _naming(exc, self.path) from None
        self.summary.samples += len(rows)
        self.summary.seconds = self._clock.add(rows)
        self.summary.board_dropped = frame.dropped()
        if self.on_rows is not None:
            self.on_rows(rows)

    def _update(self):
        decoder = self.client.decoder
        self.summary.lost_frames = decoder.lost_frames - self._counts0[0]
        self.summary.crc_errors = decoder.crc_errors - self._counts0[1]
        self.summary.skipped_bytes = decoder.skipped_bytes - self._counts0[2]

    def pump(self, seconds=None, progress=None, progress_every=1.0):
        """Only record, for `seconds` of the board's time (the records' t_us, as every wait of
        the host's counts: host/link/board_time.py; None: until Ctrl-C, which ends it cleanly);
        heartbeats keep the firmware's host timeout away. LinkError when no record comes for
        NO_DATA_S of wall time."""
        next_report = time.monotonic() + progress_every
        try:
            for _rows, _board_s in stream.records(self, seconds, self.rate, patience=NO_DATA_S):
                now = time.monotonic()
                if progress and now >= next_report:
                    next_report += progress_every
                    self._update()
                    progress(self.summary)
        except KeyboardInterrupt:
            self.summary.interrupted = True
        return self.summary

    def __exit__(self, exc_type, *exc):
        if exc_type is KeyboardInterrupt:
            self.summary.interrupted = True
        try:
            self.client.call("stream", "off")
            while True:  # the records sent before the board heard it
                frames = self.client.frames(timeout=0.05)
                if not frames:
                    break
                for frame in frames:
                    self._write(frame)
        except Exception:
            pass  # the file is what matters; a vanished port must not lose it
        finally:
            for frame in self.client.telemetry:
                self._write(frame)
            self.client.telemetry.clear()
            self._update()
            try:
                self._file.close()
            except OSError as exc:
                raise _naming(exc, self.path) from None

def _naming(exc, path):
    """`exc` (an OSError of a write to the log) with the log's path as its filename, so the error
    line names the file, not only "No space left on device"."""
    return exc if exc.filename is not None else OSError(exc.errno, exc.strerror or str(exc), str(path))


MAX_LOG_BYTES = 2 << 30  # hours at 1 kHz; a larger file would not fit the plot's arrays anyway


def load(path, warn=None):
    """A logged CSV as a dict field -> numpy int64 array. A last line cut short (the logger
    killed mid-write, the disk full) is left out, with a word to `warn` if given."""
    import warnings

    import numpy as np

    from host.errors import UserError, check_user_file

    check_user_file(path, "telemetry log", MAX_LOG_BYTES)
    try:
        with open(path) as fh:
            text = fh.read()
    except OSError as exc:
        raise UserError("cannot read %s: %s" % (path, exc.strerror or exc)) from None
    except UnicodeDecodeError:
        raise UserError("%s is not a telemetry log (host log writes one): not text" % path) from None
    lines = text.splitlines()
    header = lines[0].strip().split(",") if lines else [""]
    rows = lines[1:]
    if rows and not text.endswith("\n"):
        rows = rows[:-1]
        if warn:
            warn("%s: the last line is cut short (the log stopped mid-write): left out" % path)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # numpy warns on an empty file; we say it below
            data = np.loadtxt(rows, delimiter=",", dtype=np.int64, ndmin=2)
    except ValueError as exc:
        raise UserError("%s is not a telemetry log (host log writes one): %s" % (path, str(exc).splitlines()[0])) from None
    if data.size == 0:
        raise UserError("%s has no records (only a header): nothing to plot" % path)
    if data.shape[1] != len(header):
        raise UserError("%s: %d columns in the header, %d in the rows" % (path, len(header), data.shape[1]))
    return {name: data[:, i] for i, name in enumerate(header)}


def uncalibrated(data):
    """Whether a loaded run (load()) has only zeros where calibrated values belong."""
    return all(not data[name].any() for name in CALIBRATED_FIELDS if name in data)
