"""The one loop that reads telemetry from a board, in the board's own time.

Every reader streams through `records`: the guided calibration's sweeps and waits
(host.guided.acquire.collect), settling on a target (acquire.settle: `host move`, `host force`,
the experiments), step responses (host.guided.tuning.record_step), the API's stream and record
(host.api.Board), and `host log` (host.link.telemetry_log.Recording.pump, whose frames also go to
the CSV and the live view).
"""

import contextlib
import time

import numpy as np

from host.errors import LinkError
from host.link.board_time import NO_DATA_S, BoardTime


def records(link, seconds=None, rate=1000, patience=NO_DATA_S, silence_ends=False, started=None):
    """Yield (rows, board seconds so far) as telemetry frames arrive: rows an int32 array
    (records x firmware.protocol.FIELDS), for `seconds` of the board's time (None: until the
    caller stops reading; the last frame cut at `seconds`), streamed at `rate` Hz by `link` (a
    BoardClient, or anything with its start_stream, frames, heartbeat_if_due and stop_stream).
    Heartbeats keep the firmware's host timeout away. When nothing comes for `patience` seconds
    of wall time: LinkError, or with `silence_ends` the end of the stream. `started()`, if
    given, runs once the stream runs (a step sent then is in the records from its first
    moment). The stream is stopped however the loop ends."""
    link.start_stream(rate)
    clock = BoardTime()
    heard = time.monotonic()
    try:
        if started is not None:
            started()
        while seconds is None or clock.seconds < seconds:
            link.heartbeat_if_due()
            frames = link.frames(timeout=0.05)
            now = time.monotonic()
            if frames:
                heard = now
            elif now - heard >= patience:
                if silence_ends:
                    return
                raise LinkError("no telemetry from %s for %.0f s: the board stopped streaming"
                                % (getattr(link, "port", "the board"), patience))
            for frame in frames:
                rows = frame.records()
                stamps = clock.stamps(rows)
                if seconds is not None:  # the last frame may reach past the end
                    rows = rows[: max(1, np.searchsorted(stamps, seconds, side="right"))]
                yield rows, clock.seconds
                if seconds is not None and clock.seconds >= seconds:
                    return
    finally:
        link.stop_stream()


def closing(generator):
    """records() as a context manager, so that a reader that stops early stops the stream at once."""
    return contextlib.closing(generator)
