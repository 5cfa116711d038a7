"""Moving the actuator and logging telemetry: the guided steps, the experiments, tuning and the
bench commands (`host move`, `host force`).

Sweeps run in open loop at a low duty from one end stop to the other: they need no calibration,
and the stop is found from the data (the pots stop changing), not from a guessed time. While a
sweep runs the firmware's soft stroke limits are opened (they would stop a calibrated board 1 mm
short of the ends) and restored afterwards, by the host or, if it dies, by the firmware (they are
temporary values). Closed-loop moves wait until telemetry settles (settle). Every wait is in the
board's own time (host/link/board_time.py). Heartbeats keep the firmware's host timeout away.
"""

import contextlib
import time

import numpy as np

from firmware import protocol as P
from firmware.pi_control import DUTY_MAX
from host.errors import UserError
from host.link import stream
from host.link.board_time import NO_DATA_S

COL = {name: i for i, name in enumerate(P.FIELDS)}
_T_COL = COL["t_us"]
STREAM_HZ = 200
SWEEP_HZ = 1000  # the sweeps that are fitted take every step of a 1 kHz loop: 5x the samples, in the same time
STALL_S = 0.4  # no pot moved more than STALL_CODES for this long: at the end stop
STALL_CODES = 10


def reset(client):
    """Clear latched faults and go idle. The firmware runs `reset` after its reply is out, at
    the end of that link poll, so wait before the next command or the reset would undo it."""
    client.call("reset")
    time.sleep(0.1)


def collect(client, seconds, until=None, hz=STREAM_HZ):
    """Telemetry records (int array, columns P.FIELDS) for `seconds` of the board's own time
    (BoardTime) or until `until(records, seconds so far)`; what came if the board sends nothing
    for max(NO_DATA_S, seconds) of wall-clock time."""
    chunks = []
    with stream.closing(stream.records(client, seconds, hz, patience=max(NO_DATA_S, seconds), silence_ends=True)) as rows:
        for got, board_s in rows:
            chunks.append(got.copy())
            if until is not None and until(np.concatenate(chunks), board_s):
                break
    return np.concatenate(chunks) if chunks else np.zeros((0, P.RECORD_WORDS), dtype=np.int32)


def _recent(records, seconds):
    """The records of the last `seconds` of board time (their t_us, which wraps)."""
    t = records[:, COL["t_us"]].astype(np.int64)
    return records[(t[-1] - t) % P.T_US_WRAP <= int(seconds * 1e6)]


def _stalled(records, seconds, hz=STREAM_HZ):
    """Whether no pot moved more than STALL_CODES over the last STALL_S of board time (judged by
    the records' own times: a board whose loop is slower than the rate asked streams fewer)."""
    if seconds < STALL_S + 0.3 or len(records) < 2:
        return False
    tail = _recent(records, STALL_S)
    if len(tail) == len(records) or len(tail) < 0.5 * STALL_S * min(hz, STREAM_HZ):
        return False
    return all(np.ptp(tail[:, COL[c]]) <= STALL_CODES for c in ("raw1", "raw2"))


OPEN_STROKE = {"stroke_min_um": -P.POSITION_LIMIT_UM, "stroke_max_um": P.POSITION_LIMIT_UM, "stop_margin_um": -P.POSITION_LIMIT_UM}


@contextlib.contextmanager
def open_stroke(client):
    """Let open-loop sweeps reach the end stops on a calibrated board; restore the limits after.
    The open limits are temporary values: a host killed meanwhile gets them restored by the
    firmware once it has been silent for host_timeout_ms, so keep nothing inside that waits
    for a person (the firmware would close them again)."""
    saved = {name: client.call("get", name) for name in OPEN_STROKE}
    try:
        _open_limits(client)
        yield
    finally:
        client.call("stop")
        for name, value in saved.items():
            client.call("set", name, value)


def _open_limits(client):
    for name, value in OPEN_STROKE.items():
        client.call("set", name, value, "temp")


HOST_TIMEOUT_BIT = {name: bit for bit, name in P.FAULT_NAMES}["host_timeout"]
DRIVE_TRIES = 3


def host_went_silent(records):
    """Whether the firmware stopped the motor during `records` because the host fell silent."""
    return len(records) > 0 and bool(np.any(records[:, COL["faults"]] & HOST_TIMEOUT_BIT))


def _limits_opened(status):
    """Whether the stroke limits are open_stroke's still: the firmware puts temporary values back
    after host_timeout_ms of silence with the motor off, and every value after a timeout trip."""
    return all(name in (status.get("params_temporary") or []) for name in OPEN_STROKE)


def drive_to_stop(client, duty, max_s=20.0, hz=STREAM_HZ):
    """Open loop at `duty` until the pots stop moving (an end stop); motor off; the records (of
    every try). Inside open_stroke, as every caller is.

    A host that falls silent for host_timeout_ms (a loaded or sleeping computer) has the firmware
    stop the motor and put every parameter back to its boot value, the opened stroke limits too
    (with the motor already off, it puts the temporary values back). Mid-drive, the pots then stand
    still short of the stop, and that stall is not the end stop; after a drive or between two, the
    next drive stops at the soft limit (a zero taken so was 0.25-2.2 mm off under load,
    docs/robustness.md, "Stop 49"). So a drive begins by opening the limits again if the firmware
    has put them back, and goes on from where it stopped if the host's silence stopped it; a host
    that keeps falling silent is an error, not an end stop."""
    parts = []
    for _ in range(DRIVE_TRIES):
        if not _limits_opened(client.call("status")):
            _open_limits(client)
        reset(client)
        client.call("mode", "open_loop")
        client.call("target", int(duty))
        try:
            parts.append(collect(client, max_s, until=lambda records, seconds: _stalled(records, seconds, hz), hz=hz))
        finally:
            client.call("stop")
        if not host_went_silent(parts[-1]) and "host_timeout" not in client.call("status")["faults"]:
            return np.concatenate(parts)
    raise UserError("driving to an end stop: this computer fell silent for longer than the board's host_timeout_ms "
                    "%d times, and the board stopped the motor each time; free some CPU and run it again" % DRIVE_TRIES)


def moving_part(records, column):
    """Drop the still samples at both ends of a sweep (start at one stop, stall at the other)."""
    if len(records) == 0:
        return records
    raw = records[:, COL[column]].astype(float)
    start, end = np.median(raw[:10]), np.median(raw[-20:])
    moving = (np.abs(raw - start) > 3) & (np.abs(raw - end) > 3)
    idx = np.flatnonzero(moving)
    return records[idx[0] : idx[-1] + 1] if idx.size else records[:0]


def at_stop(records):
    """The records of the stall that ended a drive_to_stop (the actuator still at an end stop)."""
    return _recent(records, STALL_S) if len(records) else records


def sweep(client, duty, say=None, stops=None, hz=STREAM_HZ):
    """To the low stop fast, then a slow forward and a slow backward run: (records, direction).
    With a dict `stops`, its "low" and "high" get the records standing still at each end stop
    (the low one from the end of the backward run, which arrives as slowly as the forward one).
    The slow runs stream at `hz` (SWEEP_HZ where a fit wants every sample the loop makes)."""
    with open_stroke(client):
        drive_to_stop(client, -min(max(3 * abs(duty), 2500), DUTY_MAX))  # a hard sweep's fast leg: full duty at most
        if say:
            say("  sweeping forward (duty %+d)" % abs(duty))
        fwd_all = drive_to_stop(client, abs(duty), hz=hz)
        if say:
            say("  sweeping backward (duty %+d)" % -abs(duty))
        back_all = drive_to_stop(client, -abs(duty), hz=hz)
    fwd, back = moving_part(fwd_all, "raw2"), moving_part(back_all, "raw2")
    if stops is not None:
        stops["high"], stops["low"] = at_stop(fwd_all), at_stop(back_all)
    records = np.concatenate([fwd, back])
    direction = np.concatenate([np.ones(len(fwd)), -np.ones(len(back))])
    return records, direction


SETTLE_WINDOW_S = 0.1  # settle judges the mean of the records of this much board time


def settle(board, mode, target, field, tolerance, timeout_s=10.0, hold_s=0.3, progress=None, last=None):
    """Run `mode` towards `target` until telemetry `field` stays within `tolerance` of it for
    `hold_s`; returns (settled, last value, seconds). Heartbeats keep the host timeout away.
    `last`, a dict, receives the newest record (field name -> int), e.g. to say where it ended.
    `timeout_s`, `hold_s` and the seconds returned are the board's own time (BoardTime); if no
    telemetry arrives for NO_DATA_S of wall-clock time it gives up (not settled).

    The value judged is the mean of the records of the last SETTLE_WINDOW_S of board time (10 at
    the 100 Hz stream it asks for; 100 when a log's tee keeps the stream at 1 kHz): a single
    reading carries the pots' noise, which near a knee (where one code spans ~3x more travel) is
    as large as a tight tolerance, so a still actuator would rarely look settled."""
    index = P.FIELDS.index(field)
    window_us = int(SETTLE_WINDOW_S * 1e6)
    board.call("mode", mode)
    board.call("target", int(target))
    inside_since = None
    value = None
    now = 0.0
    recent = []  # (t_us, value) of the window's records
    full = False  # a record older than the window was seen: the window spans all of it
    next_progress = 0.0
    with stream.closing(stream.records(board, timeout_s, 100, silence_ends=True)) as frames:
        for rows, now in frames:
            recent.extend(zip(rows[:, _T_COL].tolist(), rows[:, index].tolist()))
            if last is not None and len(rows):
                last.update(zip(P.FIELDS, (int(v) for v in rows[-1])))
            if not recent:
                continue
            newest = recent[-1][0]
            old = 0
            while (newest - recent[old][0]) % P.T_US_WRAP >= window_us:
                old += 1
            if old:
                full = True
                del recent[:old]
            value = sum(v for _, v in recent) / len(recent)
            if full and abs(value - target) <= tolerance:
                inside_since = now if inside_since is None else inside_since
                if now - inside_since >= hold_s:
                    return True, value, now
            else:
                inside_since = None
            if progress and now >= next_progress:
                next_progress = now + 0.2  # a readable refresh, not one line per frame
                progress(value, now)
    return False, value, now


HOLD_S = 0.2


def hold(client, mode, target, field, tolerance, timeout_s=8.0, measure_s=0.3):
    """Settle `mode` at `target` (through settle: the 0.1 s mean of `field`
    within `tolerance` for HOLD_S), then log `measure_s` more seconds still in that mode:
    (settled, records of the measurement, settle time: board seconds from the command until the
    field entered the tolerance for good, or the timeout)."""
    reset(client)
    ok, _, seconds = settle(client, mode, target, field, tolerance, timeout_s=timeout_s, hold_s=HOLD_S)
    return ok, collect(client, measure_s), (seconds - HOLD_S if ok else seconds)


def mean(records, column):
    return float(np.mean(records[:, COL[column]])) if len(records) else float("nan")


def collect_pulse(client, duty, seconds, hz=STREAM_HZ):
    """A short open-loop push (manual stops); motor off after; the records (at `hz`)."""
    client.call("mode", "open_loop")
    client.call("target", int(duty))
    try:
        return collect(client, seconds, hz=hz)
    finally:
        client.call("stop")
        time.sleep(0.1)


def stalled_at_end(records):
    """True when a push moved neither pot (the block sits at an end stop)."""
    return len(records) == 0 or all(np.ptp(records[:, COL[c]]) <= STALL_CODES for c in ("raw1", "raw2"))
