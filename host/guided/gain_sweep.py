"""The deformation's offset and gain along the stroke (step "gain", between assembly and force):
F0 for every position, not only where the force step holds the gauge.

The reference the pots are calibrated against reads each pot's wiper, so pot 2's curve keeps
pot 2's mounting error (the wiper's travel is not quite the block's) and its fit's own small
slope errors, and with Df taken out the firmware's deformation D1* - D2 is

    D1* - D2 = z(x) + d (1 + e'(x))

at the block's place x: z what Df left of the assembly error (tens of um, which at 15-30 N/mm is
a few tenths of a newton), e' the slope of pot 2's curve's error there (up to 20 % on the drawn
actuators: docs/robustness.md, stops 54 and 55). The force step fits F0 at the gauge's anchor, so
both were in F0 there and nowhere else. The pots and Df cannot show them; a no-load sweep shows z,
and a force that stays the same along the stroke shows the slope. So the step sweeps end to end
both ways at no load, then again with a weight hung from the block over a pulley at the high end
(about WEIGHT_FRACTION of the force range: its value never enters). Sliding at a steady speed the
spring holds the weight plus the block's friction and drag, the same all along each run. In 1 mm
bins of D2 each direction's mean is taken apart and the two averaged (the friction's deflection
cancels): the no-load means, lightly smoothed, are the offset table z; the weighted means less z
are d (1 + e'), through which a smooth curve (a polynomial in D2 of degree DEGREE: the slope of a
bowed mount) is fitted, and the gain is that curve at the gauge's anchor over the curve, 1 where
F0 is measured. The firmware takes d = (D1* - D2 - z(D2)) g(D2) (firmware/measurement.py).

The deformation is taken as D1* - D2 from the firmware's telemetry, which carries neither table (a
gain or offset on the board from an earlier run does not enter). A weighted sweep that cannot
move the block end to end is run again at a higher duty, up to the step's --max-duty.
"""

import numpy as np

from firmware.calibration import CalibrationError, load_calibration
from host.calibration.file import gain_section, offset_section
from host.errors import UserError
from host.fitting.assembly import STOP_ZONE_UM, direction_bin_means, near_the_stops
from host.guided import acquire
from host.guided.outcome import StepOutcome

WEIGHT_FRACTION = 0.4  # of --force-range (16 N: 6.4 N): a deformation well above the pots' noise
DEGREE = 4  # the gain curve: a bowed, tilted mount's slope, as the pots' mounting errors are drawn
BIN_MM = 1.0
MIN_COUNT = 3  # samples of one direction in a bin for the bin to count
KNOT_MM = 2.0  # the firmware's table: a knot every 2 mm over the swept range, flat beyond it
SMOOTH_BINS = 3  # the offset table: each bin's mean with its neighbours' (weighted by samples)
MIN_DEFORMATION_MM = 0.05  # below this the weight is too light (or not hung) to read a slope from
GAIN_LIMITS = (0.5, 2.0)  # what the firmware takes; beyond, pot 2 sits so askew it is a mechanical problem
DUTY_STEP = 1.5  # a sweep that stalls against the weight is run again this much harder


def weight_n(opts):
    return round(WEIGHT_FRACTION * opts.force_range, 1)


def direction_means(d2_mm, defl_mm, direction, width=BIN_MM, min_count=MIN_COUNT):
    """(bin centres mm, mean deformation mm, samples) over `width` bins of D2 (whole multiples of
    it) where both directions have `min_count` samples: the mean of the two directions' means."""
    lo = np.floor(np.min(d2_mm) / width) * width
    centres, forward, backward, counts = direction_bin_means(d2_mm, defl_mm, direction, width, min_count, lo=lo)
    return centres, (forward + backward) / 2.0, counts


def smoothed(values, counts, bins=SMOOTH_BINS):
    """Each value's mean with its neighbours' within `bins` (weighted by `counts`)."""
    half = bins // 2
    v, c = np.asarray(values, dtype=float), np.asarray(counts, dtype=float)
    out = np.empty_like(v)
    for i in range(len(v)):
        lo, hi = max(0, i - half), min(len(v), i + half + 1)
        out[i] = np.sum(v[lo:hi] * c[lo:hi]) / np.sum(c[lo:hi])
    return out


def offset_and_gain(noload, weighted, anchor_mm):
    """From two sweeps, each (D2 mm, D1* - D2 mm, direction) of its samples: (offset knots mm,
    offsets mm, gain knots mm, gains, stats): the no-load bin means smoothed, and fit_gain on the
    weighted bin means less the offset at their places."""
    c0, z0, n0 = direction_means(*noload)
    cw, mw, nw = direction_means(*weighted)
    if len(c0) < 2:
        raise UserError("the no-load sweep covered %d mm both ways" % len(c0))
    z = smoothed(z0, n0)  # the table: less noise, at the price of a little of the pattern
    inside = (cw >= c0[0]) & (cw <= c0[-1])
    d = mw[inside] - np.interp(cw[inside], c0, z0)  # the slope's fit averages the noise itself
    if not len(d) or abs(float(np.median(d))) < MIN_DEFORMATION_MM:
        raise UserError("the spring hardly deformed under the weight (%s mm): is it hung?"
                        % ("%.3f" % float(np.median(d)) if len(d) else "-"))
    knots, gains, stats = fit_gain(cw[inside], d, nw[inside], anchor_mm)
    stats["offset_range_um"] = [float(np.min(z) * 1000.0), float(np.max(z) * 1000.0)]
    return c0, z, knots, gains, stats


def fit_gain(centres_mm, mean_defl_mm, counts, anchor_mm, degree=DEGREE, knot_mm=KNOT_MM):
    """(knots mm, gains, stats) from the bin means: a polynomial in D2 through them (weighted by
    their samples), the gain at each knot its value at `anchor_mm` over its value there."""
    if len(centres_mm) < degree + 3:
        raise UserError("the weighted sweep covered %d mm both ways; the gain needs at least %d"
                        % (len(centres_mm), degree + 3))
    span = (float(centres_mm[0]), float(centres_mm[-1]))
    if not span[0] <= anchor_mm <= span[1]:
        raise UserError("the weighted sweep (%.1f-%.1f mm) did not pass the gauge's anchor at %.1f mm"
                        % (span[0], span[1], anchor_mm))
    mid, half = (span[0] + span[1]) / 2.0, (span[1] - span[0]) / 2.0
    coeffs = np.polyfit((centres_mm - mid) / half, mean_defl_mm, degree, w=np.sqrt(counts))
    curve = lambda x: np.polyval(coeffs, (np.asarray(x, dtype=float) - mid) / half)  # noqa: E731
    at_anchor = float(curve(anchor_mm))
    knots = np.arange(np.ceil(span[0] / knot_mm) * knot_mm, span[1] + 1e-9, knot_mm)
    knots = np.unique(np.concatenate([[span[0]], knots, [span[1]]]))
    gains = at_anchor / curve(knots)
    resid = mean_defl_mm - curve(centres_mm)
    stats = {"deformation_mm": at_anchor, "bins": int(len(centres_mm)), "span_mm": list(span), "degree": degree,
             "rms_bin_um": float(np.sqrt(np.mean(resid ** 2)) * 1000.0), "anchor_mm": float(anchor_mm),
             "gain_range": [float(np.min(gains)), float(np.max(gains))]}
    return knots, gains, stats


def _sweep(session, prompter, opts, min_mm):
    """A weighted sweep both ways that covers `min_mm` of D2, at opts.duty or harder."""
    duty = opts.duty
    while True:
        records, direction = acquire.sweep(session.client, duty, prompter.say, hz=acquire.SWEEP_HZ)
        d2 = records[:, acquire.COL["d2_um"]] / 1000.0 if len(records) else np.zeros(0)
        covered = [float(np.ptp(d2[direction == s])) if np.any(direction == s) else 0.0 for s in (1, -1)]
        if min(covered) >= min_mm:
            return records, direction, duty
        if duty >= opts.max_duty:
            raise UserError("the block did not sweep end to end with the weight on (%.1f and %.1f mm of %.1f at duty %d): "
                            "a lighter weight, or a higher --max-duty" % (covered[0], covered[1], min_mm, duty))
        duty = min(opts.max_duty, int(duty * DUTY_STEP))
        prompter.say("  the block stalled against the weight: again at duty %d" % duty)


def _samples(records, direction):
    """(D2 mm, D1* - D2 mm, direction) of a sweep's samples away from the end stops."""
    d2 = records[:, acquire.COL["d2_um"]].astype(float)
    defl = records[:, acquire.COL["d1_um"]].astype(float) - d2  # D1* - D2: neither table in it
    keep = ~near_the_stops(d2, STOP_ZONE_UM)
    return d2[keep] / 1000.0, defl[keep] / 1000.0, direction[keep]


def calibrate_gain(session, rig, prompter, opts, calibration_path):
    """The gain step's outcome: the `deformation_offset` and `deformation_gain` sections (nothing written here)."""
    try:
        has_df = load_calibration(str(calibration_path)).df is not None
    except CalibrationError as exc:
        raise UserError("the gain step needs the pots and Df calibrated first (%s): %s" % (calibration_path, exc)) from None
    if not has_df:  # D1 - D2 would carry the assembly error, which is no slope
        raise UserError("the gain step needs Df: run host calibrate assembly first")
    w = weight_n(opts)
    prompter.say("[gain] D1* - D2 along the stroke at no load, then under a steady weight")
    rig.no_load()
    records, direction = acquire.sweep(session.client, opts.duty, prompter.say, hz=acquire.SWEEP_HZ)
    noload = _samples(records, direction)
    rig.hang_weight(w)
    lo, hi = opts.stroke
    records, direction, duty = _sweep(session, prompter, opts, 0.8 * (hi - lo))
    rig.no_load()  # (not on a stop: a stopped run's next step asks for the load it needs anyway)
    offset_knots, offsets, knots, gains, stats = offset_and_gain(noload, _samples(records, direction), opts.anchor_mm)
    stats["duty"] = duty
    ok = GAIN_LIMITS[0] <= stats["gain_range"][0] and stats["gain_range"][1] <= GAIN_LIMITS[1]
    lines = ["gain: at no load D1* - D2 still reads %+.0f to %+.0f um along the stroke (what Df left; 1 mm bins, "
             "both directions averaged): the offset table" % tuple(stats["offset_range_um"]),
             "gain: deformation %.3f mm at the anchor (%.1f mm) under the weight; gain %.3f-%.3f over %.1f-%.1f mm "
             "(%d bins of %g mm, degree %d, rms %.1f um off the curve; duty %d)" % (
                 stats["deformation_mm"], opts.anchor_mm, stats["gain_range"][0], stats["gain_range"][1],
                 stats["span_mm"][0], stats["span_mm"][1], stats["bins"], BIN_MM, DEGREE, stats["rms_bin_um"], duty)]
    if not ok:
        lines.append("gain: CHECK FAILED: beyond %.2f-%.2f: is pot 2 mounted askew, or the weight caught?" % GAIN_LIMITS)
    plots = [_plot(opts.plot_path("gain"), offset_knots, offsets, knots, gains, stats)]
    data = {"offset_knots_mm": offset_knots, "offsets_mm": offsets, "knots_mm": knots, "gains": gains, "stats": stats}
    sections = {"deformation_offset": offset_section(offset_knots, offsets, {"range_um": stats["offset_range_um"]}),
                "deformation_gain": gain_section(knots, np.clip(gains, *GAIN_LIMITS), stats)}  # refused if clipped
    return StepOutcome("gain", sections, lines, plots, ok=ok, data=data)


def _plot(path, offset_knots, offsets, knots, gains, stats):
    from matplotlib.figure import Figure  # drawn and written without pyplot: no backend is chosen

    fig = Figure(figsize=(7.5, 5.5))
    top, bottom = fig.subplots(2, 1, sharex=True)
    top.plot(offset_knots, np.asarray(offsets) * 1000.0, ".-", ms=3)
    top.set_ylabel("offset: D1* - D2 at no load (um)")
    top.grid(alpha=0.3)
    bottom.plot(knots, gains, "o-", ms=3)
    bottom.axvline(stats["anchor_mm"], color="k", lw=0.8, ls="--", label="gauge anchor (gain 1)")
    bottom.set_xlabel("D2 (mm)")
    bottom.set_ylabel("deformation gain")
    bottom.legend(fontsize=8)
    bottom.grid(alpha=0.3)
    fig.suptitle("What D1* - D2 reads along the stroke: taken off (offset), scaled (gain)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return path
