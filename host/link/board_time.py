"""The board's own time, from the telemetry records' t_us: what host waits for the actuator count in.

A virtual board on a loaded machine drops the ticks it cannot catch up (boards/sim/machine.py),
so per wall-clock second it moves less, and a wait timed by the host's clock would give it less
time than on a quiet machine. On a real board the two clocks agree. A wall-clock limit remains
only for a board that sends nothing at all (NO_DATA_S).
"""

import numpy as np

from firmware import protocol as P

NO_DATA_S = 3.0  # wall-clock seconds without a telemetry record: the board stopped streaming
_T_COL = P.FIELDS.index("t_us")
_T_WRAP = P.T_US_WRAP
_T_JUMP_US = 10000000  # a step this long is a restart of the firmware's clock, not time


class BoardTime:
    """The board's own time, in seconds, spanned by the telemetry records fed to it (their t_us)."""

    def __init__(self):
        self.seconds = 0.0
        self._last = None

    def add(self, rows):
        """Count the records `rows` (int array, columns P.FIELDS); returns the seconds so far."""
        self.stamps(rows)
        return self.seconds

    def stamps(self, rows):
        """Count the records `rows` as add() does; returns each one's board time, in seconds."""
        if not len(rows):
            return np.zeros(0)
        t = rows[:, _T_COL].astype(np.int64)
        steps = np.diff(t, prepend=t[0] if self._last is None else self._last) % _T_WRAP
        steps[steps >= _T_JUMP_US] = 0
        times = self.seconds + np.cumsum(steps) / 1e6
        self.seconds = float(times[-1])
        self._last = int(t[-1])
        return times
