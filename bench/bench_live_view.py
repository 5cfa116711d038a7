"""How often the live view redraws while the virtual board streams at 1 kHz, and whether any frame
is lost meanwhile (host/link/live_view.py, the path of `host log/move/force --live`).

    .venv/bin/python bench/bench_live_view.py                        # Agg canvas, the machine as it is
    .venv/bin/python bench/bench_live_view.py --busy 2               # plus two CPU-bound processes
    xvfb-run -a .venv/bin/python bench/bench_live_view.py --canvas window   # a real Tk window

The run: a model calibration on the virtual board, telemetry at 1 kHz logged to CSV over the
connection that drives a back-and-forth of moves across the stroke (the axes rescale as the
block travels) for about --seconds of board time. "agg" draws the same figure the window does,
on matplotlib's file-only canvas; "window" opens the interactive backend's window (on Linux it
needs a display: Xvfb serves). Prints the redraws drawn and skipped against the schedule
(live_view.REFRESH_HZ a second of board time), the rate drawn per board second and per wall
second, the time a redraw took, the redraws that drew the axes, and the frames lost, dropped or
corrupted. Exit status 0 whatever the figures.
"""

import argparse
import math
import os
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "bench"))

from suite_soak import loadavg, start_burners, stop_burners  # noqa: E402

from host.api import Board  # noqa: E402
from host.link.live_view import REFRESH_HZ, logged  # noqa: E402
from host.link.telemetry_log import load  # noqa: E402
from testkit.model import write_model_calibration  # noqa: E402

TARGETS_MM = (45.0, 15.0, 50.0, 10.0, 30.0)
TARGET_HZ = 10  # issue 13: the picture updated at >= 10 Hz while the board streams at 1 kHz


def run(seconds, canvas, tmp):
    cal = Path(tmp) / "cal.json"
    write_model_calibration(cal)
    out = Path(tmp) / "live.csv"
    with Board("sim", calibration=str(cal)) as board:
        def work(recording):
            start = time.monotonic()
            k = 0
            while recording.summary.samples < seconds * 1000:
                board.move(TARGETS_MM[k % len(TARGETS_MM)], hold=True)
                recording.pump(0.5)
                k += 1
            return k, time.monotonic() - start

        (moves, wall), summary, view, _ = logged(board, out, 1000, work, canvas=canvas)  # wall: while streaming
    data = load(out)
    gaps = int(sum(1 for d in (data["t_us"][1:] - data["t_us"][:-1]) if d != 1000))
    return moves, wall, summary, view, len(data["t_us"]), gaps


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=20.0, help="board seconds to stream (default 20)")
    ap.add_argument("--canvas", choices=("agg", "window"), default="agg",
                    help="agg: the window's drawing on the file-only canvas (default); window: a real window")
    ap.add_argument("--busy", type=int, default=0, metavar="N", help="N CPU-bound processes meanwhile")
    args = ap.parse_args(argv)
    if args.canvas == "window" and sys.platform.startswith("linux") and not os.environ.get("DISPLAY"):
        sys.exit("error: --canvas window needs a display: run under xvfb-run -a (apt install xvfb) or a desktop")
    burners = start_burners(args.busy) if args.busy else []
    try:
        load_before = loadavg()
        with tempfile.TemporaryDirectory(prefix="lsea-live-bench-") as tmp:
            moves, wall, summary, view, rows, gaps = run(args.seconds, args.canvas, tmp)
        load_after = loadavg()
    finally:
        stop_burners(burners)
    print("canvas %s, %d busy processes, load average %s -> %s, %d moves" % (
        args.canvas, args.busy, load_before, load_after, moves))
    print("telemetry: %d records in the CSV, lost frames %d, board drops %d, CRC errors %d, steps not 1 ms apart %d" % (
        rows, summary.lost_frames, summary.board_dropped, summary.crc_errors, gaps))
    if not view or view.get("headless"):
        print("live view: no window opened (no display)")
        return 0
    board_s = view["board_seconds"]
    scheduled = math.floor(board_s * REFRESH_HZ)
    print("live view: %.1f board s in %.1f wall s; %d redraws of %d scheduled (%d skipped as late), %d with the axes" % (
        board_s, wall, view["redraws"], scheduled, view["skipped"], view["full_redraws"]))
    print("drawing: %.0f ms a redraw on average, the longest %.0f ms (wall time in the drawing process)" % (
        1000 * view["drawing_s"] / max(1, view["redraws"]), 1000 * view["longest_s"]))
    print("redraw rate: %.1f per board second, %.1f per wall second (scheduled %d, target >= %d)" % (
        view["redraws"] / board_s, view["redraws"] / wall, REFRESH_HZ, TARGET_HZ))
    return 0


if __name__ == "__main__":
    sys.exit(main())
