"""Calibration 2 (the paper's section 3): the assembly error Df = D1 - D2 between the calibrated pots.

With both pots calibrated and no load, the block sweeps end to end (forward and backward at a
low duty, so the small friction deformation has both signs and averages out). D1 and D2 are
computed on the host by the firmware's own integer converters from the calibration file (no
second copy of the arithmetic), Df = D1 - D2 is fitted by a polynomial in D1 (or a free-knot
table, df_table) and exported as the `df` section.

The order is chosen with the fit (host/fitting/assembly.py).
"""

import numpy as np

from firmware.calibration import CalibrationError, convert, load_calibration
from host.errors import UserError
from host.calibration.file import force_table_section, poly_section
from host.fitting.assembly import STOP_ZONE_UM, binned_peak, df_table, fit_df, near_the_stops
from host.guided import acquire, stroke
from host.guided.outcome import StepOutcome


def pots_calibration(calibration_path):
    """The calibration file's constants, which must hold both pots' curves."""
    try:
        return load_calibration(str(calibration_path))
    except CalibrationError as exc:
        raise UserError("the assembly step needs both pots calibrated first (%s): %s" % (calibration_path, exc)) from None


def positions_um(cal, raw1, raw2):
    """(D1, D2) in um from raw codes through the firmware's converters and the file's constants."""
    d1 = np.array([convert(cal.pot1[0], int(c), cal.pot1[1]) for c in raw1], dtype=float)
    d2 = np.array([convert(cal.pot2[0], int(c), cal.pot2[1]) for c in raw2], dtype=float)
    return d1, d2


def min_sweep_mm(limits, stroke_um):
    """The range in D1 the Df sweep must cover: SWEEP_FRACTION of the distance between the end
    stops the pots step measured (the file's stroke section, in D2), as that step checks each
    pot's sweep against its own stops (pot_calibration.sweep_limits), never more than the nominal
    limits.min_range_mm. Without a stroke section (a manual reference), the nominal range: one
    drawn actuator's 43.8 mm stroke had its stops 38.7 mm apart in D2 and failed the nominal
    39.4 mm with a full 37.9 mm sweep."""
    if stroke_um is None:
        return limits.min_range_mm
    return min(limits.min_range_mm, stroke.SWEEP_FRACTION * (stroke_um[1] - stroke_um[0]) / 1000.0)


def calibrate_assembly(session, rig, prompter, opts, calibration_path):
    rig.no_load()
    prompter.say("[assembly] no-load sweep end to end with the calibrated pots")
    records, direction = acquire.sweep(session.client, opts.duty, prompter.say)
    if len(records) < 50:
        return StepOutcome("assembly", {}, ["assembly: almost no data (did the block move?)"], [], ok=False)
    cal = pots_calibration(calibration_path)
    d1, d2 = positions_um(cal, records[:, acquire.COL["raw1"]], records[:, acquire.COL["raw2"]])
    near = near_the_stops(d2, STOP_ZONE_UM)
    d1, d2, direction = d1[~near], d2[~near], direction[~near]
    x = d1 / 1000.0
    df = (d1 - d2) / 1000.0
    coeffs, resid, order, scores = fit_df(x, df, opts.df_order)
    lo, hi = float(np.min(x)), float(np.max(x))
    span = hi - lo
    # The firmware clamps D1 to the fitted range: past the data a high-order polynomial is a guess
    # that grows fast, a constant is a small, bounded error (the nut reaches at most the cavity's
    # 2 mm past the block's end stops)
    domain = (lo, hi)
    chosen = order
    while True:  # a high order can need more bits than 31 give: the next lower one that exports
        try:
            section = poly_section(coeffs, domain, 1000.0, 1000.0, ("um", "um"), {})
            break
        except UserError:
            if order <= 1 or opts.df_order != "auto":
                raise
            order -= 1
            coeffs = np.polyfit(x, df, order)
            resid = df - np.polyval(coeffs, x)
    lines = [
        "Df: %d samples over D1 %.1f..%.1f mm (%d within %.1f mm of an end stop left out)" % (
            len(x), lo, hi, np.count_nonzero(near), STOP_ZONE_UM / 1000.0),
        "Df: cross-validated rms by order: " + ", ".join("%d: %.1f um" % (n, 1000 * s) for n, s in scores.items()),
        "Df: order %d, peak |Df| before %.3f mm, peak residual after %.3f mm of single samples, %.3f mm of "
        "1 mm bin means (rms %.1f um)" % (order, np.max(np.abs(df)), np.max(np.abs(resid)), binned_peak(x, resid),
                                          1000 * np.sqrt(np.mean(resid**2))),
    ]
    if order != chosen:
        lines.append("Df: order %d needs more than 31 bits in the firmware's integers: order %d used" % (chosen, order))
    table = df_table(x, df) if opts.df_order == "auto" else None
    if table is not None:
        try:
            table_section = force_table_section(table[0], table[1], domain, ("um", "um"), {}, df=True)
        except UserError as exc:  # e.g. a D1 range the table's input offset cannot hold: keep the polynomial
            lines.append("Df: a table would fit better but cannot be exported (%s): the polynomial is kept" % exc)
            table = None
    if table is not None:
        kx, ky, table_scores = table
        resid = df - np.interp(x, kx, ky)
        section = table_section
        lines.append("Df: a %d-knot table predicts held-out samples better than any polynomial (cross-validated "
                     "rms by knots: %s): it follows the kinks the pot tables leave in D1 - D2" % (
                         len(kx), ", ".join("%d: %.1f um" % (n, 1000 * v) for n, v in table_scores.items())))
        lines.append("Df: the table leaves a peak of %.3f mm of single samples, %.3f mm of 1 mm bin means (rms %.1f um)"
                     % (np.max(np.abs(resid)), binned_peak(x, resid), 1000 * np.sqrt(np.mean(resid**2))))
        order = len(kx)
    min_span = min_sweep_mm(opts.limits, cal.stroke)
    ok = span >= min_span
    if not ok:
        lines.append("Df: FAIL the sweep covered only %.1f mm of the %.1f mm it needs: let the block run end to end"
                     % (span, min_span))
    stats = {"order": order, "model": "table" if table is not None else "poly",
             "peak_before_mm": float(np.max(np.abs(df))), "peak_after_mm": float(np.max(np.abs(resid))),
             "peak_after_binned_mm": binned_peak(x, resid),
             "rms_after_mm": float(np.sqrt(np.mean(resid**2))), "n_samples": int(len(x))}
    section["fit"] = stats
    png = opts.plot_path("df")
    curve = (lambda g: np.interp(g, table[0], table[1])) if table is not None else (lambda g: np.polyval(coeffs, g))
    plot_df(png, x, df, curve, resid, direction, "%d-knot table" % order if table is not None else "order %d" % order)
    data = {"d1_mm": x, "df_mm": df, "resid_mm": resid, "coeffs": coeffs, "direction": direction, "stats": stats}
    return StepOutcome("assembly", {"df": section}, lines, [png], ok=ok, data=data)


def plot_df(path, x, df, curve, resid, direction=None, label="order"):
    from matplotlib.figure import Figure  # drawn and written without pyplot: no backend is chosen

    fig = Figure(figsize=(7.5, 4.5))
    ax = fig.subplots()
    ax.plot(x, df, ".", ms=2, color="tab:orange", label="Df = D1 - D2 before (peak %.2f mm)" % np.max(np.abs(df)))
    ax.plot(x, resid, ".", ms=2, color="tab:blue", label="after: Df - Df_hat (peak %.3f mm)" % np.max(np.abs(resid)))
    grid = np.linspace(np.min(x), np.max(x), 400)
    ax.plot(grid, curve(grid), "k-", lw=1, label="Df_hat, %s" % label)
    ax.axhline(0, color="0.5", lw=0.6)
    ax.set_xlabel("D1 (mm)")
    ax.set_ylabel("mm")
    ax.set_title("Assembly error between the pots (paper Fig. 5)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return path
