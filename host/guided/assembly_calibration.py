"""Calibration 2 (the paper's section 3): the assembly error Df = D1 - D2 between the calibrated pots.

With both pots calibrated and no load, the block sweeps end to end (forward and backward at a
low duty, so the small friction deformation has both signs and averages out). D1 and D2 are
computed on the host by the firmware's own integer converters from the calibration file (no
second copy of the arithmetic), Df = D1 - D2 is fitted by a polynomial in D1 (or a free-knot
table, df_table) and exported as the `df` section.

Order: the paper fits a quartic. But the mounting errors are smooth functions of the true
positions, while the fit's variable is D1, which pot 1's own error bends: a quartic in the true
position is not one in D1 (on the simulated actuator order 4 leaves 0.36 mm of model error,
order 8 26 um), and what the pot fits leave enters Df too. So `auto` (the default) starts from
the paper's 4 and goes higher, up to MAX_ORDER, when 5-fold cross-validation says a higher order
predicts held-out samples more than 5 % better; an integer fixes the order.
"""

import numpy as np

from firmware.calibration import CalibrationError, convert, load_calibration
from host.errors import UserError
from host.calibration_file import force_table_section, poly_section
from host.guided import acquire
from host.guided.outcome import StepOutcome

MAX_ORDER = 12
PAPER_ORDER = 4


def positions_um(calibration_path, raw1, raw2):
    """(D1, D2) in um from raw codes through the firmware's converters and the file's constants."""
    try:
        cal = load_calibration(str(calibration_path))
    except CalibrationError as exc:
        raise UserError("the assembly step needs both pots calibrated first (%s): %s" % (calibration_path, exc)) from None
    d1 = np.array([convert(cal.pot1[0], int(c), cal.pot1[1]) for c in raw1], dtype=float)
    d2 = np.array([convert(cal.pot2[0], int(c), cal.pot2[1]) for c in raw2], dtype=float)
    return d1, d2


def cv_rms(x, y, order, folds=5):
    """Root mean square hold-out error of a degree-`order` polynomial (interleaved folds)."""
    idx = np.arange(len(x))
    err = []
    for k in range(folds):
        test = idx % folds == k
        c = np.polyfit(x[~test], y[~test], order)
        err.append(y[test] - np.polyval(c, x[test]))
    return float(np.sqrt(np.mean(np.concatenate(err) ** 2)))


def choose_order(x, y, order, floor=1, top=MAX_ORDER):
    """(order, {order: cv rms}): the given order, or for 'auto' the lowest order >= `floor` whose
    cross-validated rms is within 5 % of the best one's."""
    scores = {n: cv_rms(x, y, n) for n in range(1, top + 1)}
    if order == "auto":
        best = min(s for n, s in scores.items() if n >= floor)
        order = min(n for n, s in scores.items() if n >= floor and s <= 1.05 * best)
    return int(order), scores


def binned_peak(x, resid, width=1.0):
    """Largest |mean residual| over bins `width` mm wide in D1: the curve's error, without the
    per-sample noise of two pot readings (bins with fewer than 5 samples are skipped)."""
    idx = np.floor((x - np.min(x)) / width).astype(int)
    counts = np.bincount(idx)
    sums = np.bincount(idx, weights=resid)
    full = counts >= 5
    return float(np.max(np.abs(sums[full] / counts[full]))) if full.any() else float("nan")


def fit_df(d1_mm, df_mm, order):
    order, scores = choose_order(d1_mm, df_mm, order, floor=PAPER_ORDER)
    coeffs = np.polyfit(d1_mm, df_mm, order)
    resid = df_mm - np.polyval(coeffs, d1_mm)
    return coeffs, resid, order, scores


def calibrate_assembly(session, rig, prompter, opts, calibration_path):
    rig.no_load()
    prompter.say("[assembly] no-load sweep end to end with the calibrated pots")
    records, direction = acquire.sweep(session.client, opts.duty, prompter.say)
    if len(records) < 50:
        return StepOutcome("assembly", {}, ["assembly: almost no data (did the block move?)"], [], ok=False)
    d1, d2 = positions_um(calibration_path, records[:, acquire.COL["raw1"]], records[:, acquire.COL["raw2"]])
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
        "Df: %d samples over D1 %.1f..%.1f mm" % (len(x), lo, hi),
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
    ok = span >= opts.limits.min_range_mm
    if not ok:
        lines.append("Df: FAIL the sweep covered only %.1f mm: let the block run end to end" % span)
    stats = {"order": order, "model": "table" if table is not None else "poly",
             "peak_before_mm": float(np.max(np.abs(df))), "peak_after_mm": float(np.max(np.abs(resid))),
             "peak_after_binned_mm": binned_peak(x, resid),
             "rms_after_mm": float(np.sqrt(np.mean(resid**2))), "n_samples": int(len(x))}
    section["fit"] = stats
    png = opts.out_dir / "calibration-df.png"
    curve = (lambda g: np.interp(g, table[0], table[1])) if table is not None else (lambda g: np.polyval(coeffs, g))
    plot_df(png, x, df, curve, resid, direction, "%d-knot table" % order if table is not None else "order %d" % order)
    data = {"d1_mm": x, "df_mm": df, "resid_mm": resid, "coeffs": coeffs, "direction": direction, "stats": stats}
    return StepOutcome("assembly", {"df": section}, lines, [png], ok=ok, data=data)


TABLE_KNOTS = range(6, 21, 2)
TABLE_GAIN = 0.9  # a table replaces the polynomial when its hold-out error is at most this fraction


def df_table(x, df, folds=5):
    """(knots_x, knots_y, {knots: cross-validated rms}) of the free-knot table with the fewest
    knots within 5 % of the best, when it predicts held-out samples at least TABLE_GAIN better
    than the best polynomial; else None. Both are scored on the same folds (interleaved over
    D1), and a table's knots are chosen again inside each fold, so its score is as honest as the
    polynomial's. The pots' own tables leave kinks at their knots in D1 - D2, which a polynomial
    in D1 smooths over (seen on noisy random actuators: 0.13 mm of bin means at order 10, the
    cross-validated error still falling at order 12)."""
    from host.piecewise_linear import fit_pwl, lsq_knot_values

    order = np.argsort(x, kind="stable")
    xs, ys = x[order], df[order]
    idx = np.arange(len(xs))
    tests = [idx % folds == f for f in range(folds)]

    def cv(predict):
        return float(np.sqrt(np.mean(np.concatenate([ys[t] - predict(xs[~t], ys[~t], xs[t]) for t in tests]) ** 2)))

    poly_cv = min(cv(lambda a, b, c, n=n: np.polyval(np.polyfit(a, b, n), c)) for n in range(1, MAX_ORDER + 1))

    def table(a, b, c, k):
        kx = np.asarray(fit_pwl(a, b, k).coefficients["knots_x"])
        return np.interp(c, kx, lsq_knot_values(a, b, kx))

    scores = {k: cv(lambda a, b, c, k=k: table(a, b, c, k)) for k in TABLE_KNOTS}
    best = min(scores.values())
    if best > TABLE_GAIN * poly_cv:
        return None
    k = min(n for n, v in scores.items() if v <= 1.05 * best)
    kx = np.asarray(fit_pwl(xs, ys, k).coefficients["knots_x"])
    return kx, lsq_knot_values(xs, ys, kx), scores


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
