"""Gain tuning on a board: record step responses of the position or force loop for one or more
gain sets, judge each (host/fitting/step_response.py) and pick the best.

A trial holds the start value until it has settled, then streams telemetry, changes the target
by one step and records for a fixed span of the board's own time (BoardTime). Between trials
and at the end the motor stops; the gains in force before tuning are put back unless the caller
keeps the recommended ones (`keep`); a trial's gains are temporary values, which the firmware
itself puts back if the host goes silent. Times are the board's: on a real board the wall clock's.
"""

import itertools

import numpy as np

from firmware import protocol as P
from host.errors import UserError
from host.fitting.step_response import analyse, best
from host.guided.acquire import settle
from host.link import stream
from host.link.board_time import BoardTime

# mode -> (telemetry field judged, gain parameters, unit of the field, scale to the shown unit)
LOOPS = {
    "position": ("d2_um", ("kp_pos", "ki_pos"), "mm", 1e-3),
    "force": ("force_mN", ("kp_force", "ki_force"), "N", 1e-3),
}


class Trial:
    """One gain set's step response: `gains` {name: value}, `response` a StepResponse (values in
    the telemetry field's own unit: um or mN), `held` whether the start was held (settled) before
    the step; a loop that hunts around the start is stepped anyway, and its response says how."""

    def __init__(self, gains, response, held=True):
        self.gains = gains
        self.response = response
        self.held = held

    @property
    def label(self):
        return " ".join("%s=%d" % kv for kv in self.gains.items())

    @property
    def settled(self):
        return self.held and self.response.settled

    def verdict(self):
        v = self.response.verdict()
        return v if self.held else v + " (did not settle at the start either)"


def record_step(board, mode, start, target, duration_s, hold_tolerance, hz=500, settle_timeout_s=10.0):
    """(t seconds from the step, values, held) of `mode`'s field after the target steps from
    `start` to `target` (field units: um or mN); `held`: the start had settled before the step."""
    field = LOOPS[mode][0]
    index = P.FIELDS.index(field)
    held, _, _ = settle(board, mode, start, field, hold_tolerance, settle_timeout_s)
    clock = BoardTime()  # from the step: the stream's own clock starts a little before it
    rows = []
    stepped = False
    with stream.closing(stream.records(board, None, hz, started=lambda: board.call("target", int(target)))) as frames:
        for r, _ in frames:
            if not stepped:  # records from before the new target reached the step are dropped
                keep = np.flatnonzero(r[:, P.FIELDS.index("target")] == int(target))
                if not len(keep):
                    continue
                r = r[keep[0]:]
                stepped = True
            clock.add(r)
            rows.append(r)
            if clock.seconds >= duration_s:
                break
    if not rows:
        raise UserError("no telemetry after the step")
    data = np.concatenate(rows)
    t_us = np.unwrap(data[:, P.FIELDS.index("t_us")].astype(float), period=2.0**30)
    return (t_us - t_us[0]) / 1e6, data[:, index].astype(float), held


def gain_sets(names, current, grid):
    """[{name: value}] to try: the current gains alone, or every combination of `grid`
    ({name: [values]}, current value for a name not given)."""
    if not grid:
        return [dict(current)]
    lists = [grid.get(n) or [current[n]] for n in names]
    return [dict(zip(names, combo)) for combo in itertools.product(*lists)]


def tune(board, mode, start, step, duration_s, band, grid=None, keep=False, progress=None):
    """Run a step response for each gain set; returns (trials, index of the best or None).
    The board's gains before the call are restored at the end unless `keep` and a best exists."""
    field, names, _, _ = LOOPS[mode]
    current = {n: board.call("get", n) for n in names}
    sets = gain_sets(names, current, grid)
    trials = []
    chosen = None
    try:
        for i, gains in enumerate(sets):
            for n, v in gains.items():  # temporary: the firmware puts them back if this host dies
                board.call("set", n, int(v), "temp")
            if progress:
                progress(i, len(sets), gains)
            try:
                t, y, held = record_step(board, mode, start, start + step, duration_s,
                                         hold_tolerance=max(band, abs(step) * 0.05), settle_timeout_s=3.0 if grid else 10.0)
            finally:
                board.call("stop")
            trials.append(Trial(dict(gains), analyse(t, y, start, start + step, band), held))
        held = [i for i, tr in enumerate(trials) if tr.held]
        pick = best([(trials[i].label, trials[i].response) for i in held])
        chosen = None if pick is None else held[pick]
    finally:
        board.call("stop")
        final = trials[chosen].gains if keep and chosen is not None else current
        for n, v in final.items():
            board.call("set", n, int(v))
    return trials, chosen
