"""Watch a run live: the telemetry plot (host/link/telemetry_plot.py) redrawn fifteen times a second
of the board's time while the board streams at 1 kHz and the CSV is written.

Two processes, so drawing never holds up the serial port: this one does all of the board's I/O
(the motion or the plain recording, through the connection's host.link.stream.Tee, whose sinks
write every frame to the CSV and put its records on a queue), and a drawing process of its own (a GUI
toolkit wants its own main thread, and a redraw holds the interpreter lock long enough to starve
the port's reader, and a virtual board's relay, of a thread beside it) takes them off the queue
and redraws. Frames are counted by sequence number as they are decoded, so a slow redraw shows
as a late picture, never as lost data. Redraws are scheduled in the board's time (the records'
t_us): one each 1/refresh_hz board seconds; when a redraw took longer than that, the ones it
covered are counted as skipped rather than drawn late.

A machine without a display (no DISPLAY, or matplotlib's backend is not interactive) gets no
window; the commands write a PNG of the whole run at the end instead.

`keep` (--keep) leaves the window open after the run: the drawing process outlives it and the
command gets a KeptWindow to wait on once the board is closed and its motor stopped, so looking
at the picture never holds the board.
"""

import os
import queue
import sys
import time

import numpy as np

from firmware import protocol as P
from host.link.board_time import BoardTime
from host.link.telemetry_plot import TelemetryFigure

REFRESH_HZ = 15  # scheduled; a loaded machine skips some and still shows >= 10 (bench/bench_live_view.py)
WINDOW_S = 10.0  # the newest seconds of board time shown
MAX_POINTS = 1000  # per line, about one a pixel; the CSV keeps every record
DRAWER_END_S = 30.0  # after the run, how long the drawing process may take to finish
IO_SWITCH_S = 0.0005  # the interpreter's thread switch interval while drawing beside the board's I/O
KEPT_IDLE_S = 0.05  # a kept window handles its events this often: resizing stays smooth, an idle CPU stays idle


def open_window(title):
    """A matplotlib Figure in a window of the interactive backend, or None where there is no
    display. The one place the host lets pyplot choose a backend: a window was asked for."""
    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        return None
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(10, 9))
    if fig.canvas.required_interactive_framework is None:  # Agg and the other file-only backends
        plt.close(fig)
        return None
    fig.canvas.manager.set_window_title(title)
    plt.show(block=False)
    return fig


class LiveView:
    """The newest `window_s` of records on a TelemetryFigure on `figure`, redrawn every
    1/refresh_hz seconds of board time. `redraws` and `skipped` count what the schedule asked
    for; `full_redraws` how many of the redraws drew the axes too.

    Ticks and labels cost most of a redraw (~10 ms for the lines, 100-300 ms with the axes), so
    the axes are drawn only when their limits change; in between only the lines, and the board
    time as text, are drawn over the saved background (blitting). Time scrolls: the x axis is
    fixed, seconds before the newest record, so time moving on never redraws the axes; a panel's
    range grows when the data leave it and shrinks when they use less than a quarter of it."""

    def __init__(self, figure, raw=False, title=None, window_s=WINDOW_S, refresh_hz=REFRESH_HZ, max_points=MAX_POINTS):
        self.figure = figure
        self.plot = TelemetryFigure(figure, raw, title, animated=True)
        self.window_s = window_s
        self.period = 1.0 / refresh_hz
        self.max_points = max_points
        self.clock = BoardTime()
        self.redraws = 0
        self.full_redraws = 0
        self.skipped = 0
        self.drawing_s = 0.0  # wall time spent drawing, and the longest draw
        self.longest_s = 0.0
        self._drawn_at = None  # board seconds of the newest record on the picture
        self.closed = False
        self._next = self.period
        self._chunks = []  # (board seconds, records) as they came, trimmed to the window
        self._background = None
        step = window_s / 20
        self.plot.axes[-1].set_xlim(-window_s - step, step)
        self.plot.axes[-1].set_xlabel("seconds before the newest record (board clock)")
        self.now_text = figure.text(0.99, 0.005, "", ha="right", va="bottom", fontsize=9, animated=True)
        figure.canvas.mpl_connect("close_event", self._on_close)
        figure.canvas.mpl_connect("resize_event", self._on_resize)
        figure.tight_layout()

    def _on_close(self, event):
        self.closed = True

    def _on_resize(self, event):
        self._background = None

    def add(self, rows):
        """Records as they arrive, in order (int array, columns P.FIELDS)."""
        if len(rows):
            self._chunks.append((self.clock.stamps(rows), rows))

    def due(self):
        return self.clock.seconds >= self._next

    def _window(self):
        now = self.clock.seconds
        start = now - self.window_s
        while len(self._chunks) > 1 and self._chunks[1][0][0] <= start:
            del self._chunks[0]
        t = np.concatenate([c[0] for c in self._chunks])
        rows = np.concatenate([c[1] for c in self._chunks])
        t, rows = t[t >= start], rows[t >= start]
        pick = np.arange(len(t) - 1, -1, -max(1, len(t) // self.max_points))[::-1]  # the newest always
        return t[pick] - now, rows[pick]

    def _limits_changed(self):
        """Set the axes' limits for the data now on the lines; True when any changed."""
        changed = False
        for ax in self.plot.axes:
            values = [line.get_ydata() for line, _ in self.plot.lines if line.axes is ax]
            values = np.concatenate([np.asarray(v, dtype=float) for v in values])
            values = values[np.isfinite(values)]
            if not len(values):
                continue
            lo, hi = float(values.min()), float(values.max())
            margin = max((hi - lo) * 0.5, 1e-3 * max(1.0, abs(hi)))  # room for noise: fewer full redraws
            a, b = ax.get_ylim()
            if lo < a or hi > b or b - a > 4 * (hi - lo + 2 * margin):
                ax.set_ylim(lo - margin, hi + margin)
                changed = True
        return changed

    def redraw(self):
        """Draw the window; counts the scheduled redraws this one stands for beyond itself as skipped."""
        behind = int((self.clock.seconds - self._next) // self.period)
        self.skipped += max(0, behind)
        self._next += (max(0, behind) + 1) * self.period
        self.redraws += 1
        self._paint()

    def finish(self):
        """Draw the end of the run once more if records came after the last redraw (outside the
        schedule, not counted in `redraws`), so the picture left on screen shows the whole run."""
        if self._chunks and self._drawn_at != self.clock.seconds:
            self._paint()

    def _paint(self):
        self._drawn_at = self.clock.seconds
        started = time.perf_counter()
        canvas = self.figure.canvas
        if self._chunks:
            t, rows = self._window()
            self.plot.show(t, {name: rows[:, i] for i, name in enumerate(P.FIELDS)}, autoscale=False)
            if self._limits_changed():
                self._background = None
        if self._background is None:
            canvas.draw()  # everything but the lines
            self._background = canvas.copy_from_bbox(self.figure.bbox)
            self.full_redraws += 1
        else:
            canvas.restore_region(self._background)
        for line, _ in self.plot.lines:
            line.axes.draw_artist(line)
        self.now_text.set_text("board time %.1f s" % self.clock.seconds)
        self.figure.draw_artist(self.now_text)
        canvas.blit(self.figure.bbox)
        canvas.flush_events()
        took = time.perf_counter() - started
        self.drawing_s += took
        self.longest_s = max(self.longest_s, took)

    def idle(self):
        """Let the window handle its events (resizing, closing) between redraws."""
        self.figure.canvas.flush_events()


def _draw(rows_queue, report, stop, raw, title, canvas, close_stops, keep, release):
    """The drawing process: records off `rows_queue` (None ends it) onto a LiveView, redrawn when
    due; puts ("headless",) or ("done", counts, kept) on `report`. canvas: "window" or "agg".
    kept: `keep` and the window is still open, and then stays open, answering its events,
    until the person closes it or `release` is set."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the board process's to handle
    if canvas == "agg":
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        figure = Figure(figsize=(10, 9))
        FigureCanvasAgg(figure)
    else:
        figure = open_window(title)
        if figure is None:
            report.put(("headless",))
            return
    view = LiveView(figure, raw, title)
    report.put(("ready",))
    ended = False
    while not ended:
        try:
            rows = rows_queue.get(timeout=0.02)
            while rows is not None:
                if not view.closed:
                    view.add(rows)
                rows = rows_queue.get_nowait()
            ended = True
        except queue.Empty:
            pass
        if view.closed:
            if close_stops:
                stop.set()
        elif view.due():
            view.redraw()
        else:
            view.idle()
    if not view.closed:
        view.finish()
    newest = {line.get_label(): float(line.get_ydata()[-1]) for line, _ in view.plot.lines if len(line.get_ydata())}
    kept = keep and canvas == "window" and not view.closed
    report.put(("done", {"redraws": view.redraws, "skipped": view.skipped, "full_redraws": view.full_redraws,
                         "board_seconds": view.clock.seconds, "newest": newest, "drawing_s": view.drawing_s,
                         "longest_s": view.longest_s}, kept))
    # the counts go first: the run is over and the board is let go while the window stays; its
    # events are still handled, or it would not redraw, resize or close
    while kept and not view.closed and not release.wait(KEPT_IDLE_S):
        view.idle()


class KeptWindow:
    """A live window left open after its run (--keep), in its drawing process: `wait()` until the
    person closes it (or presses Ctrl-C), `release()` to close it from here."""

    def __init__(self, drawer, release):
        self._drawer = drawer
        self._release = release

    def alive(self):
        return self._drawer.is_alive()

    @property
    def exitcode(self):
        """The drawing process's exit status once it ended (0: it ended by itself), else None."""
        return self._drawer.exitcode

    def wait(self):
        """Say so on stderr and wait until the window is closed; Ctrl-C ends the wait as closing does."""
        from host.terminal import note

        try:  # the note inside: a Ctrl-C as soon as it is on screen is the wait's to end
            note("the live window stays open: close it to end")
            while self._drawer.is_alive():
                self._drawer.join(0.2)  # in slices, so that Ctrl-C is seen on every platform
        except KeyboardInterrupt:
            pass
        finally:
            self.release()

    def release(self):
        """Close the window: its process ends by itself, or is ended after DRAWER_END_S."""
        self._release.set()
        self._drawer.join(DRAWER_END_S)
        if self._drawer.is_alive():
            self._drawer.terminate()
            self._drawer.join(DRAWER_END_S)


def logged(board, path, rate, work, canvas=None, raw=False, close_stops=False, keep=False):
    """Run `work(recording)` with the board's telemetry at `rate` Hz logged to CSV `path` over the
    same connection (host.api.Board.log), drawn live when `canvas` is "window" (or "agg": the
    same drawing on the file-only canvas) in a process of its own, so that drawing never holds
    up this process's reading of the port. `raw`: a board without calibration (TelemetryFigure).
    `keep`: the window stays open after the run, until closed.
    Returns (what work returned, the LogSummary, the view's report: None without a canvas,
    {"headless": True} when no window could open, else its counts; a KeptWindow when a window
    was kept, else None)."""
    if canvas is None:
        with board.log(path, rate) as recording:
            return work(recording), recording.summary, None, None
    import multiprocessing

    context = multiprocessing.get_context("spawn")  # a fresh interpreter: its own GUI, no forked threads
    rows_queue, report, stop, release = context.Queue(), context.Queue(), context.Event(), context.Event()
    drawer = context.Process(target=_draw, args=(rows_queue, report, stop, raw, "lsea-kit: %s" % path, canvas,
                                                 close_stops, keep, release), daemon=True)
    drawer.start()
    try:  # the window is up (or known not to open) before the run starts
        ready = report.get(timeout=DRAWER_END_S)
    except queue.Empty:
        ready = ("ready",)
    if ready[0] == "headless":
        drawer.join(DRAWER_END_S)
        with board.log(path, rate) as recording:
            return work(recording), recording.summary, {"headless": True}, None
    try:
        with board.log(path, rate, on_rows=rows_queue.put, stop=stop) as recording:
            result = work(recording)
    except BaseException:
        release.set()  # a run that failed keeps no window: nobody will wait on it
        raise
    finally:
        rows_queue.put(None)
    try:
        outcome = report.get(timeout=DRAWER_END_S)
    except queue.Empty:
        outcome = None
    if outcome is not None and outcome[2]:  # the drawer keeps its window: the caller waits, after the board
        return result, recording.summary, outcome[1], KeptWindow(drawer, release)
    drawer.join(DRAWER_END_S)
    if drawer.is_alive():
        drawer.terminate()
    return result, recording.summary, None if outcome is None else outcome[1], None


def watched(board, path, rate, live, work, close_stops=False, keep=False):
    """`work(link)` with the telemetry logged to CSV `path` (logged()); `live`: drawn in a window,
    or, where there is no display, a PNG of the whole run written beside the CSV at the end;
    `keep`: the window stays open after the run (nothing to keep without a display).
    Returns (what work returned, the LogSummary, the PNG's path or None, a KeptWindow to wait
    on once the board is closed, or None)."""
    from pathlib import Path

    from host.link.telemetry_plot import plot
    from host.terminal import warn

    display = live and not (sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or
                                                                      os.environ.get("WAYLAND_DISPLAY")))
    raw = (board.client.status_info or {}).get("calibration_crc") is None
    result, summary, view, kept = logged(board, path, rate, work, "window" if display else None, raw, close_stops,
                                         keep)
    png = None
    if live and (not display or (view or {}).get("headless")):
        warn("no display: a PNG of the run is written at the end instead of a live window%s"
             % (" (--keep: no window to keep)" if keep else ""))
        if summary.samples:
            png = plot(path, Path(path).with_suffix(".png"))
    return result, summary, png, kept
