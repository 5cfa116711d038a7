"""The one loop that reads telemetry from a board, in the board's own time, and where its records go.

Every reader streams through `records`: the guided calibration's sweeps and waits
(host.guided.acquire.collect), settling on a target (acquire.settle: `host move`, `host force`,
the experiments), step responses (host.guided.tuning.record_step), the API's stream and record
(host.api.Board, through host.link.connect.Connection.stream), and `host log` (Tee.pump).

A sink is any callable that takes a frame's records (an int32 array, records x
firmware.protocol.FIELDS): the CSV log (host.link.telemetry_log.CsvLog), numpy arrays
(`Arrays`), the live view's queue. `records(..., sinks=...)` hands each its rows; a `Tee` hands
them every frame streamed through it while it is on, whoever reads, so one connection serves a
motion and its log.
"""

import contextlib
import time
from dataclasses import dataclass

import numpy as np

from firmware import protocol as P
from host.errors import LinkError, UserError
from host.link.board_time import NO_DATA_S, BoardTime


def records(link, seconds=None, rate=1000, patience=NO_DATA_S, silence_ends=False, started=None, sinks=()):
    """Yield (rows, board seconds so far) as telemetry frames arrive: rows an int32 array
    (records x firmware.protocol.FIELDS), for `seconds` of the board's time (None: until the
    caller stops reading; the last frame cut at `seconds`), streamed at `rate` Hz by `link` (a
    BoardClient, a Tee, or anything with their start_stream, frames, heartbeat_if_due and
    stop_stream); each of `sinks` is called with the rows first.
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
                for sink in sinks:
                    sink(rows)
                yield rows, clock.seconds
                if seconds is not None and clock.seconds >= seconds:
                    return
    finally:
        link.stop_stream()


def closing(generator):
    """records() as a context manager, so that a reader that stops early stops the stream at once."""
    return contextlib.closing(generator)


class Arrays:
    """A sink that keeps every record; run() gives them as {field: numpy int64 array} (the shape
    host.link.telemetry_log.load gives a CSV), plus "t_s": each record's board time in seconds,
    from 0 at the first."""

    def __init__(self):
        self.chunks = []

    def __call__(self, rows):
        self.chunks.append(rows.copy())  # a frame's array is the decoder's buffer

    def run(self):
        rows = np.concatenate(self.chunks) if self.chunks else np.zeros((0, P.RECORD_WORDS), dtype=np.int32)
        out = {name: rows[:, i].astype(np.int64) for i, name in enumerate(P.FIELDS)}
        out["t_s"] = BoardTime().stamps(rows)
        return out


@dataclass
class LogSummary:
    """What a Tee passed on: records, the board's seconds they span, and what was lost."""

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


class Tee:
    """Telemetry streamed at `rate` Hz to `sinks` while other code drives the board through this
    object (host.link.connect.Connection.tee puts it in the connection's place).

    It stands in for the BoardClient where a motion streams (host.guided.acquire.settle,
    Connection.stream): call, request, heartbeat_if_due, start_stream, frames and stop_stream,
    nothing else. The stream stays on at the tee's rate whatever a caller's start_stream asks,
    and every frame handed out by frames() first goes to each sink; between motions the frames
    wait in the client and reach the sinks with the next read, so the sinks see the whole run.
    `stop` (a threading.Event) set from another thread makes the next frames() raise
    KeyboardInterrupt, so whatever drives the board ends through its usual clean-up (motor off).
    `summary` (LogSummary) counts what went to the sinks."""

    def __init__(self, client, rate=1000, sinks=(), stop=None):
        self.client = client
        self.rate = rate
        self.sinks = list(sinks)
        self.stop = stop
        self.summary = LogSummary()
        self._clock = BoardTime()  # the summary's seconds: the board's, as `host log --seconds` counts
        self._counts0 = None

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
        decoder = self.client.decoder
        self._counts0 = decoder.lost_frames, decoder.crc_errors, decoder.skipped_bytes
        self.client.start_stream(self.rate)
        return self

    def frames(self, timeout=0.1):
        if self.stop is not None and self.stop.is_set():
            raise KeyboardInterrupt
        frames = self.client.frames(timeout=timeout)
        for frame in frames:
            self._pass_on(frame)
        return frames

    def start_stream(self, hz):
        """The stream is on already, at the tee's rate: what came so far goes to the sinks, and
        the caller sees only frames from now on."""
        self.frames(timeout=0)
        return {"hz": self.rate}

    def stop_stream(self):
        return {"hz": self.rate}  # stays on until the tee ends

    def _pass_on(self, frame):
        rows = frame.records()
        for sink in self.sinks:
            sink(rows)
        self.summary.samples += len(rows)
        self.summary.seconds = self._clock.add(rows)
        self.summary.board_dropped = frame.dropped()

    def _update(self):
        if self._counts0 is None:
            return
        decoder = self.client.decoder
        self.summary.lost_frames = decoder.lost_frames - self._counts0[0]
        self.summary.crc_errors = decoder.crc_errors - self._counts0[1]
        self.summary.skipped_bytes = decoder.skipped_bytes - self._counts0[2]

    def pump(self, seconds=None, progress=None, progress_every=1.0):
        """Only stream to the sinks, for `seconds` of the board's time (None: until Ctrl-C, which
        ends it cleanly); `progress(summary)` about every `progress_every` s of wall time.
        LinkError when no record comes for NO_DATA_S of wall time."""
        next_report = time.monotonic() + progress_every
        try:
            for _rows, _board_s in records(self, seconds, self.rate, patience=NO_DATA_S):
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
                    self._pass_on(frame)
        except (UserError, OSError):
            pass  # what the sinks hold is what matters; a vanished port must not lose it
        finally:
            try:
                for frame in self.client.telemetry:
                    self._pass_on(frame)
            finally:
                self.client.telemetry.clear()
                self._update()
