"""Record board telemetry to CSV: one row per record, columns = firmware.protocol.FIELDS.

`CsvLog(path, status, rate)` is the sink (host/link/stream.py) that writes them: host.api.Board.log
puts it on the connection's Tee, so that a motion and its log share one connection, and the Tee's
LogSummary (host.link.stream) says what came (samples, rate, lost frames counted by sequence number, board drops).
Rows are written as they arrive, so a Ctrl-C or a lost port still leaves a complete file up to
the last frame.
Beside the CSV (a plain table any tool reads) it writes RUN.meta.json: the board, firmware and
protocol version, calibration CRC, loop period, stream rate, the date, each column's unit, and
the code tables of the `mode` and `faults` columns.
"""

import csv
import datetime
import json
from pathlib import Path

from firmware.protocol import FAULT_NAMES, FIELD_UNITS, FIELDS, MODES
from host.calibration.file import keep_dated_copy
from host.terminal import note

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


class CsvLog:
    """A telemetry sink (host.link.stream): every record it is given, one CSV row, written as it
    arrives (a Ctrl-C or a lost port still leaves a complete file up to the last frame), with
    RUN.meta.json beside it from the board's `status` at the start and the stream `rate`. Use as a
    context manager; a write that fails (a full disk) names the file."""

    def __init__(self, path, status, rate):
        self.path = path
        for existing in (Path(path), metadata_path(path)):
            # a log aimed at a file that holds something (a calibration, by a slip of the hand,
            # or an earlier run) keeps it, as every calibration writer does
            kept = keep_dated_copy(existing)
            if kept is not None:
                note("%s existed: kept as %s" % (existing, kept.name))
        metadata_path(path).write_text(json.dumps(metadata(status, rate), indent=1) + "\n")
        self._file = open(path, "w", newline="")
        self._writer = csv.writer(self._file)
        self._writer.writerow(FIELDS)

    def __call__(self, rows):
        try:
            self._writer.writerows(rows.tolist())
        except OSError as exc:  # a full disk shows here, at a buffer's flush: say which file
            raise _naming(exc, self.path) from None

    def close(self):
        try:
            self._file.close()
        except OSError as exc:
            raise _naming(exc, self.path) from None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


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
    if header[0] != FIELDS[0]:  # a sweep, a calibration, anything else: said as what it is not
        raise UserError("%s is not a telemetry log (host log writes one): its first line is %r, not the log's "
                        "column names (%s,...)" % (path, lines[0][:40] if lines else "", FIELDS[0]))
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
