"""Record board telemetry to CSV: one row per record, columns = firmware.protocol.FIELDS.

`record(board, path, seconds, rate)` streams from a BoardClient, writes rows as they arrive (so a
Ctrl-C or a lost port still leaves a complete file up to the last frame), keeps the host timeout
away with heartbeats, and returns a `LogSummary` (samples, rate, lost frames, board drops).
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

from firmware.protocol import FIELDS, MODES
from firmware.safety import FAULT_NAMES

# Each column's unit (a new telemetry field must say its unit here: tests check)
UNITS = {
    "t_us": "us since the firmware started, wraps at 2**30",
    "raw1": "ADC code (board-native bits), pot 1",
    "raw2": "ADC code, pot 2",
    "raw_ref": "ADC code, reference input (0 without one)",
    "d1_um": "um, nut position D1* (Df corrected)",
    "d2_um": "um, output block position D2",
    "defl_um": "um, spring deformation D1* - D2",
    "force_mN": "mN, F0(d)",
    "target": "the mode's target: duty (open_loop), um (position), mN (force)",
    "duty": "signed duty, 10000 = 100 %",
    "mode": "code: see modes",
    "faults": "bit mask: see faults",
}

# What the firmware computes from the calibration; all 0 in records from a board without one.
CALIBRATED_FIELDS = ("d1_um", "d2_um", "defl_um", "force_mN")


@dataclass
class LogSummary:
    samples: int = 0
    seconds: float = 0.0
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
    crc = status.get("calibration_crc")
    return {
        "date": datetime.datetime.now(datetime.timezone.utc).replace(microsecond=0).isoformat(),
        "board": status.get("board"), "firmware": status.get("version"), "protocol": status.get("protocol"),
        "interpreter": status.get("interpreter"),
        "calibration_crc": None if crc is None else "%08x" % (crc & 0xFFFFFFFF),
        "calibration_error": status.get("calibration_error"),
        "loop_period_us": status.get("period_us"), "stream_hz": rate,
        "columns": {name: UNITS[name] for name in FIELDS},
        "modes": {str(i): name for i, name in enumerate(MODES)},
        "faults": {str(bit): name for bit, name in FAULT_NAMES},
    }


def record(board, path, seconds=None, rate=1000, progress=None, progress_every=1.0):
    """Stream telemetry at `rate` Hz into CSV `path` for `seconds` (None: until Ctrl-C); the
    metadata go to RUN.meta.json first."""
    meta = metadata(board.call("status"), rate)
    metadata_path(path).write_text(json.dumps(meta, indent=1) + "\n")
    summary = LogSummary()
    decoder = board.decoder
    lost0, crc0, skip0 = decoder.lost_frames, decoder.crc_errors, decoder.skipped_bytes
    with open(path, "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(FIELDS)
        board.start_stream(rate)
        start = time.monotonic()
        next_report = start + progress_every
        try:
            while seconds is None or time.monotonic() - start < seconds:
                board.heartbeat_if_due()
                for frame in board.frames(timeout=0.05):
                    rows = frame.records()
                    writer.writerows(rows.tolist())
                    summary.samples += len(rows)
                    summary.board_dropped = frame.dropped()
                now = time.monotonic()
                summary.seconds = now - start
                summary.lost_frames = decoder.lost_frames - lost0
                if progress and now >= next_report:
                    next_report += progress_every
                    progress(summary)
        except KeyboardInterrupt:
            summary.interrupted = True
        finally:
            summary.seconds = time.monotonic() - start
            try:
                board.stop_stream()
            except Exception:
                pass  # the file is what matters; a vanished port must not lose it
            summary.lost_frames = decoder.lost_frames - lost0
            summary.crc_errors = decoder.crc_errors - crc0
            summary.skipped_bytes = decoder.skipped_bytes - skip0
            fh.flush()
    return summary


def load(path):
    """A logged CSV as a dict field -> numpy int64 array."""
    import warnings

    import numpy as np

    from host.errors import UserError

    try:
        with open(path) as fh:
            header = fh.readline().strip().split(",")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # numpy warns on an empty file; we say it below
            data = np.loadtxt(path, delimiter=",", skiprows=1, dtype=np.int64, ndmin=2)
    except OSError as exc:
        raise UserError("cannot read %s: %s" % (path, exc.strerror or exc)) from None
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
