"""Plot telemetry (host log's CSV, or records as they arrive): positions, deformation, force,
duty and targets against the board's time.

`TelemetryFigure` lays the four panels out on a matplotlib Figure once and `show()` replaces the
lines' data, so the live view (host/link/live_view.py) redraws the same figure fifteen times a second
and `plot()` draws a whole run once into a PNG. Neither touches pyplot or matplotlib's backend:
`plot()` draws on a Figure of its own and writes the file through it.

A run logged from a board without a calibration has all-zero positions, deformation and force
(the firmware only sends raw ADC codes then): plot() says so through `warn` and draws the raw
codes (pots, reference sensor) in their place instead of flat zeros."""

import numpy as np

from firmware.protocol import MODES
from host.link.telemetry_log import CALIBRATED_FIELDS, load, uncalibrated

_T_WRAP = 2.0**30  # the firmware's t_us wraps here


def _in_mode(name, scale=1.0):
    """The target column where the board ran in mode `name`, NaN elsewhere (the line breaks)."""
    code = MODES.index(name)
    return lambda d: np.where(d["mode"] == code, d["target"] / scale, np.nan)


# (y label, [(line label, style, values of a run dict)]) per panel
CALIBRATED_PANELS = (
    ("position, mm", [("D1* nut", "-", lambda d: d["d1_um"] / 1000),
                      ("D2 block", "-", lambda d: d["d2_um"] / 1000),
                      ("position target", "k--", _in_mode("position", 1000))]),
    ("deformation, mm", [("deformation D1* - D2", "-", lambda d: d["defl_um"] / 1000)]),
    ("force, N", [("F0(d)", "-", lambda d: d["force_mN"] / 1000),
                  ("force target", "k--", _in_mode("force", 1000))]),
    ("duty (of 10000)", [("duty", "-", lambda d: d["duty"]),
                         ("duty target", "k--", _in_mode("open_loop"))]),
)
RAW_PANELS = (
    ("pot ADC code", [("raw1 (pot 1, nut)", "-", lambda d: d["raw1"]),
                      ("raw2 (pot 2, block)", "-", lambda d: d["raw2"])]),
    ("reference ADC code", [("raw_ref (reference sensor)", "-", lambda d: d["raw_ref"])]),
    ("code difference", [("raw1 - raw2 (no calibration: no deformation or force)", "-",
                          lambda d: d["raw1"].astype(np.int64) - d["raw2"])]),
    CALIBRATED_PANELS[3],
)


def seconds(t_us):
    """Board seconds from the first record, across the t_us wrap."""
    t = np.unwrap(np.asarray(t_us, dtype=float), period=_T_WRAP) / 1e6
    return t - t[0] if len(t) else t


class TelemetryFigure:
    """The four panels on `figure` (a matplotlib Figure); raw=True draws the ADC codes of a
    board without calibration instead of positions, deformation and force."""

    def __init__(self, figure, raw=False, title=None, animated=False):
        self.figure = figure
        self.axes = figure.subplots(4, 1, sharex=True)
        self.lines = []
        for ax, (ylabel, lines) in zip(self.axes, RAW_PANELS if raw else CALIBRATED_PANELS):
            for label, style, values in lines:
                # animated: left out of a full draw, drawn over a saved background (blitting)
                (line,) = ax.plot([], [], style, label=label, lw=1, animated=animated)
                self.lines.append((line, values))
            ax.set_ylabel(ylabel)
            ax.grid(True, alpha=0.3)
            ax.legend(loc="upper right", fontsize=8)
        self.axes[-1].set_xlabel("time, s (board clock)")
        if title:
            figure.suptitle(title)

    def show(self, t, run, autoscale=True):
        """Draw the run dict `run` (field -> array) against `t` (seconds) on every line."""
        for line, values in self.lines:
            line.set_data(t, values(run))
        if autoscale:
            for ax in self.axes:
                ax.relim()
                ax.autoscale_view()


def plot(csv_path, out_path, warn=None):
    """Draw the run in `csv_path` into the PNG `out_path`; returns out_path."""
    from matplotlib.figure import Figure

    d = load(csv_path, warn)
    raw = uncalibrated(d)
    if raw and warn:
        warn("%s: %s are all 0 (logged from a board without calibration?): plotting the raw ADC codes "
             "(raw1, raw2, raw_ref) instead" % (csv_path, ", ".join(CALIBRATED_FIELDS)))
    fig = Figure(figsize=(10, 10))
    TelemetryFigure(fig, raw, title=str(csv_path)).show(seconds(d["t_us"]), d)
    fig.tight_layout()
    fig.savefig(out_path, dpi=100)
    return out_path
