"""The fit figure (paper Fig. 3b/3c style): sweep and fitted curve on top, residuals below.

Residuals are drawn in micrometres when the reference unit is mm (a calibration's error is a
few tens of um on a 60 mm stroke, invisible on the mm scale), else in the reference unit. The
noise floor, when known, is drawn as a +-1 sigma band so one can see what is left to learn.
The figure is a matplotlib Figure of its own, written straight to the file: no pyplot, so
importing or calling this leaves matplotlib's backend (a notebook's, say) as it was.
"""

import numpy as np
from matplotlib.figure import Figure


def plot_fit(path, x, y, result, unit="mm", noise=None, title=None, direction=None):
    """Write the figure for `result` fitted to sorted (x, y) to `path` (PNG); returns path."""
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    scale, runit = (1000.0, "um") if unit == "mm" else (1.0, unit)
    fig = Figure(figsize=(7.5, 6.5))
    top, bottom = fig.subplots(2, 1, sharex=True, gridspec_kw={"height_ratios": [3, 2]})
    grid = np.linspace(result.x_range[0], result.x_range[1], 1500)
    if direction is None:
        top.plot(x, y, ".", ms=2, color="0.55", label="sweep (%d samples)" % x.size)
    else:
        for d, colour, name in ((1, "tab:blue", "forward"), (-1, "tab:orange", "backward")):
            m = direction == d
            top.plot(x[m], y[m], ".", ms=2, color=colour, alpha=0.5, label="%s (%d)" % (name, np.count_nonzero(m)))
    label = "%s order %d" % (result.model, result.order)
    top.plot(grid, result(grid), "-", color="black", lw=1.2, label=label)
    if result.model == "bcm" and "handles" in result.coefficients:
        c = result.coefficients
        hx = c["lx"] + c["rx"] * np.linspace(0, 1, len(c["handles"]))
        top.plot(hx, c["handles"], "s--", color="tab:red", ms=4, lw=0.6, label="handles (at t = i/n)")
    top.set_ylabel("reference (%s)" % unit)
    top.legend(loc="upper left", fontsize=8)
    top.grid(alpha=0.3)
    top.set_title(title or "%s: rms %.4g %s, max %.4g %s" % (label, result.rms, unit, result.max_abs, unit))
    r = (y - result(x)) * scale
    if direction is None:
        bottom.plot(x, r, ".", ms=2, color="tab:blue")
    else:  # hysteresis shows as two bands, one per direction
        for d, colour in ((1, "tab:blue"), (-1, "tab:orange")):
            m = direction == d
            bottom.plot(x[m], r[m], ".", ms=2, color=colour, alpha=0.6)
    bottom.axhline(0, color="black", lw=0.8)
    if noise:
        bottom.axhspan(-noise * scale, noise * scale, color="tab:green", alpha=0.15, label="noise floor +-1 sigma")
        bottom.legend(loc="upper right", fontsize=8)
    bottom.set_ylabel("residual (%s)" % runit)
    bottom.set_xlabel("raw reading")
    bottom.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return path
