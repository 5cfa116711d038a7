"""`host tune position|force`: step responses of a closed loop, their figures, a plot, and with
--kp/--ki a small grid of gains tried and the best recommended (host/guided/tuning.py)."""

import json

from firmware.pi_control import GAIN_MAX
from host.commands._options import add_port_arguments, nonzero, open_board, parsed, ranged
from host.errors import DONE, MISSED, UserError
from host.guided.tuning import LOOPS, tune
from host.terminal import end_progress, output, progress_line

DEFAULTS = {  # mode -> (start, step, band) in the shown unit (mm or N)
    "position": (25.0, 5.0, 0.05),
    "force": (-1.0, -2.0, 0.1),
}


def gain_list(text):
    """'500,768,1000' -> [500, 768, 1000] (ValueError saying what is wrong)."""
    try:
        values = [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise ValueError("gain list %r: whole numbers separated by commas, e.g. 500,768,1000" % text) from None
    if not values:
        raise ValueError("gain list %r is empty: whole numbers separated by commas, e.g. 500,768,1000" % text)
    if any(not 0 <= v <= GAIN_MAX for v in values):
        raise ValueError("gain list %r: values must be within 0..%d" % (text, GAIN_MAX))
    return values


def add_parser(subparsers):
    p = subparsers.add_parser(
        "tune", help="step response of the position or force loop: rise, overshoot, settling, error; try gains",
        description="Holds --start, steps the target by --step and records the response for --duration seconds of "
        "the board's time, then reports rise time (10-90 %), overshoot, settling time (last exit from target +- "
        "--band), steady-state error (mean of the last fifth) and whether the loop oscillates, and plots it. "
        "--kp/--ki take comma-separated lists: every combination is tried and the best (settles, overshoot at most "
        "20 %, then the shortest settling time) is recommended. The gains in force before are put back unless "
        "--apply (keep the best until the board restarts) or --save (keep it on the board). Force mode needs "
        "something to push against (--port sim: --load gauge).")
    p.add_argument("mode", choices=sorted(LOOPS), help="the loop to tune")
    p.add_argument("--start", type=ranged(float, -200, 200), default=None,
                   help="value held before the step: mm (position, default 25) or N (force, default -1)")
    p.add_argument("--step", type=nonzero(ranged(float, -200, 200)), default=None,
                   help="size of the step: mm (default 5) or N (default -2)")
    p.add_argument("--duration", type=ranged(float, 0.2, 60), default=1.5, metavar="S",
                   help="seconds recorded after the step (default 1.5)")
    p.add_argument("--band", type=ranged(float, 0.0001, 100), default=None,
                   help="settled within target +- this: mm (default 0.05) or N (default 0.1)")
    p.add_argument("--kp", type=parsed(gain_list, "gain list"), default=None, metavar="LIST", help="proportional gains to try, e.g. 500,768,1000")
    p.add_argument("--ki", type=parsed(gain_list, "gain list"), default=None, metavar="LIST", help="integral gains to try, e.g. 8,16,32")
    p.add_argument("--png", default=None, metavar="FILE", help="plot of the responses (default tune-MODE.png)")
    p.add_argument("--apply", action="store_true", help="keep the recommended gains on the board (until it restarts)")
    p.add_argument("--save", action="store_true", help="keep the recommended gains on the board across restarts")
    p.add_argument("--json", action="store_true", help="print the figures as JSON")
    add_port_arguments(p)
    p.set_defaults(func=run)


def plot(trials, chosen, mode, path):
    from matplotlib.figure import Figure  # a figure of its own: matplotlib's backend stays as it is

    _, _, unit, scale = LOOPS[mode]
    fig = Figure(figsize=(10, 5))
    ax = fig.subplots()
    for i, tr in enumerate(trials):
        r = tr.response
        ax.plot(r.t, r.y * scale, lw=2.2 if i == chosen else 1.0,
                label="%s: %s%s" % (tr.label, tr.verdict(), " (recommended)" if i == chosen else ""))
    r = trials[0].response
    ax.axhline(r.target * scale, color="k", ls="--", lw=0.8)
    ax.axhspan((r.target - r.band) * scale, (r.target + r.band) * scale, color="k", alpha=0.08, label="settling band")
    ax.set_xlabel("time after the step, s (board clock)")
    ax.set_ylabel("%s, %s" % ("output position D2" if mode == "position" else "force F0(d)", unit))
    ax.set_title("%s loop step response" % mode)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    return path


def _line(tr, unit, scale):
    r = tr.response
    def num(v, fmt):
        return "-" if v is None else fmt % v
    return "%-28s rise %7s s  overshoot %5.1f %%  settling %7s s  steady error %+8.4f %s  %s" % (
        tr.label, num(r.rise_s, "%.3f"), 100 * r.overshoot, num(r.settling_s, "%.3f"), r.steady_error * scale, unit,
        tr.verdict())


def _pushed_to_a_stroke_end(board):
    """(D2 mm, the end) when the block rests at a soft stroke limit after force trials that never
    settled: force mode with no load drives it there (the trials stop the motor, it stays); else None."""
    from host.guided import acquire

    records = acquire.collect(board.client, 0.05)
    if not len(records):
        return None
    d2_um = acquire.mean(records, "d2_um")
    end = board.stroke_end(d2_um)
    return (d2_um / 1000.0, end) if end else None


def run(args):
    field, names, unit, scale = LOOPS[args.mode]
    start, step, band = DEFAULTS[args.mode]
    start = args.start if args.start is not None else start
    step = args.step if args.step is not None else step
    band = args.band if args.band is not None else band
    grid = {}
    if args.kp is not None:  # --kp "" is a mistake argparse reported, not the defaults
        grid[names[0]] = args.kp
    if args.ki is not None:
        grid[names[1]] = args.ki
    png = args.png or "tune-%s.png" % args.mode

    def progress(i, n, gains):
        progress_line("trial %d/%d: %s" % (i + 1, n, " ".join("%s=%d" % kv for kv in gains.items())))

    with open_board(args, require_calibration=True) as opened:
        board = opened.client
        if args.mode == "position":
            lo, hi = (v / 1000.0 for v in board.call("status")["stroke_um"])
            if not (lo <= start <= hi and lo <= start + step <= hi):
                raise UserError("--start and --start + --step must stay within the soft stroke limits in force, "
                                "%.1f..%.1f mm (host status)" % (lo, hi))
        trials, chosen = tune(board, args.mode, int(round(start / scale)), int(round(step / scale)), args.duration,
                              band / scale, grid=grid, keep=args.apply or args.save, progress=progress)
        end_progress()
        saved = board.call("save") if args.save and chosen is not None else None
        stroke_end = _pushed_to_a_stroke_end(opened) if chosen is None and args.mode == "force" else None
    png = plot(trials, chosen, args.mode, png)
    if args.json:
        rows = [dict(tr.response.as_dict(), gains=tr.gains, held=tr.held, verdict=tr.verdict()) for tr in trials]
        output(json.dumps({"mode": args.mode, "unit": field, "trials": rows,
                          "recommended": None if chosen is None else trials[chosen].gains, "png": png}, indent=1))
    else:
        output("%s loop, step %g -> %g %s, band +-%g %s:" % (args.mode, start, start + step, unit, band, unit))
        for tr in trials:
            output(_line(tr, unit, scale))
        if chosen is None and stroke_end:  # the usual mistake, said as host force says it
            output("no gain set settled: the block ran to D2 = %.1f mm, at the soft stroke limit (%s): nothing to push "
                   "against? hook a load (--port sim: --load gauge)" % stroke_end)
        elif chosen is None:
            output("no gain set settled without oscillating or overshooting more than 20 %: try smaller gains")
        elif len(trials) > 1:
            kept = "kept on the board" + (" and saved" if saved is not None else "") if (args.apply or args.save) else \
                "not applied (--apply or --save keeps it)"
            output("recommended: %s (%s)" % (trials[chosen].label, kept))
        if png:
            output("plot: %s" % png)
    if chosen is None:
        return MISSED
    return DONE
