"""Model comparison over orders: the paper's Fig. 3a for every calibration model we have.

For each model and order the fit is made through `host.fitting.models.fit_model` (so every model gets
the same statistics) and scored three ways:
- `norm2`: the residual 2-norm ||y - f(x)||, the paper's objective O_b / O_p;
- `rms`: norm2 / sqrt(m), in reference units;
- `rms_over_noise`: rms divided by the sweep's noise floor (1.0 means nothing left to learn).

"order" means what each model means by it (degree for bcm/pcm/cheb, number of knots or points
for spline/pchip/lut/pwl), so the table also carries n_params, the numbers a board would store,
and the plot has a second panel against n_params for like-for-like comparison.
"""

import csv
import math
import os
from pathlib import Path

import numpy as np

from host.fitting.models import MODELS, fit_model

DEFAULT_MODELS = ("bcm", "pcm", "cheb", "spline", "lut", "pwl")
# Models whose fitter can start from the previous order's fit: their objective then never rises
# with the order (a free-knot search otherwise lands in a worse local optimum now and then).
# BCM: the previous degree, elevated, is one more start; without it each degree would refit every
# degree below it (the fitter's own warm-start chain), quadratic work over 2-15.
WARM_START = {
    "pwl": lambda fit: {"start_knots": fit.coefficients["knots_x"]},
    "bcm": lambda fit: {"warm": fit},
}
COLUMNS = ("model", "order", "n_params", "norm2", "rms", "rms_over_noise", "max_abs", "monotone", "fit_seconds", "error")


def parse_orders(text):
    """'2-15' or '2,3,5' or '2-6,10' -> sorted list of distinct ints >= 1."""
    orders = set()
    for part in str(text).split(","):
        part = part.strip()
        if not part:
            continue
        try:
            if "-" in part:
                a, b = (int(v) for v in part.split("-", 1))
                if b < a:
                    raise ValueError
                orders.update(range(a, b + 1))
            else:
                orders.add(int(part))
        except ValueError:
            raise ValueError("bad order range %r: use e.g. 2-15 or 2,3,5" % part) from None
    if not orders or min(orders) < 1:
        raise ValueError("orders must be positive integers, e.g. 2-15")
    return sorted(orders)


def parse_models(text):
    """'bcm,pcm' or 'all' -> list of registry names (order kept, duplicates dropped)."""
    if str(text).strip() == "all":
        return list(MODELS)
    names = []
    for name in str(text).split(","):
        name = name.strip()
        if not name:
            continue
        if name not in MODELS:
            raise ValueError("unknown model %r (choose from %s, or all)" % (name, ", ".join(MODELS)))
        if name not in names:
            names.append(name)
    if not names:
        raise ValueError("no models given")
    return names


def _fit_orders(x, y, name, orders, noise, opts, on_order=None):
    """Rows for one model over `orders`, in order (warm-started where WARM_START says so)."""
    m = len(x)
    rows, previous = [], None
    for order in orders:
        row = dict.fromkeys(COLUMNS, float("nan"))
        row.update(model=name, order=int(order), error="", monotone=False)
        if on_order:
            on_order(name, order)
        try:
            warm = WARM_START[name](previous) if previous is not None and name in WARM_START else {}
            fit = fit_model(name, x, y, order, **opts, **warm)
        except (ValueError, np.linalg.LinAlgError) as exc:
            row["error"] = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        else:
            row.update(
                n_params=int(fit.n_params),
                norm2=fit.rms * math.sqrt(m),
                rms=fit.rms,
                max_abs=fit.max_abs,
                monotone=bool(fit.monotone),
                fit_seconds=fit.fit_seconds,
            )
            if noise:
                row["rms_over_noise"] = fit.rms / noise
            previous = fit
        rows.append(row)
    return rows


def _tasks(models, orders, jobs):
    """(model, orders) work units: warm-started models stay whole, the others are split so that
    the slow model (the BCM at high degree) spreads over the workers."""
    tasks = []
    for name in models:
        if name in WARM_START or jobs <= 1:
            tasks.append((name, list(orders)))
        else:
            tasks.extend((name, list(orders[i::jobs])) for i in range(jobs) if orders[i::jobs])
    return tasks


def compare_models(x, y, orders, models=DEFAULT_MODELS, noise=None, progress=None, options=None, on_order=None,
                   jobs=1):
    """Fit every model at every order; returns a list of row dicts (keys: COLUMNS).

    A fit that fails (e.g. more parameters than samples) gives a row with NaN scores and the
    reason in `error`, so one bad cell never hides the rest of the table. `progress(model, i,
    n, seconds)` is called after each model (seconds: sum of its fit times), `on_order(model,
    order)` before each fit (only with jobs=1); `options` maps model -> extra fitter options.
    jobs > 1 fits in that many worker processes; the rows are the same, in the same order.
    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    orders = list(orders)
    by_model = {}
    if jobs <= 1:
        for i, name in enumerate(models):
            by_model[name] = _fit_orders(x, y, name, orders, noise, (options or {}).get(name, {}), on_order)
            if progress:
                progress(name, i + 1, len(models), sum(r["fit_seconds"] for r in by_model[name] if not r["error"]))
    else:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor, as_completed

        tasks = _tasks(models, orders, jobs)
        pending = {name: sum(1 for t in tasks if t[0] == name) for name in models}
        done = 0
        # spawn, not fork: a forked child can inherit a locked BLAS thread pool
        with ProcessPoolExecutor(jobs, mp_context=multiprocessing.get_context("spawn")) as pool:
            futures = {
                pool.submit(_fit_orders, x, y, name, sub, noise, (options or {}).get(name, {})): name
                for name, sub in tasks
            }
            for future in as_completed(futures):
                name = futures[future]
                by_model.setdefault(name, []).extend(future.result())
                pending[name] -= 1
                if pending[name] == 0:
                    done += 1
                    if progress:
                        progress(name, done, len(models),
                                 sum(r["fit_seconds"] for r in by_model[name] if not r["error"]))
    rows = []
    for name in models:
        rows.extend(sorted(by_model[name], key=lambda r: r["order"]))
    return rows


def _fmt(value, digits=4):
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, float):
        if math.isnan(value):
            return "-"
        return "%.*g" % (digits, value)
    return str(value)


def write_csv(rows, path):
    with open(path, "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=COLUMNS)
        writer.writeheader()
        for row in rows:
            writer.writerow({k: _fmt(row[k], 8) if isinstance(row[k], float) else row[k] for k in COLUMNS})


def pivot_markdown(rows, key, digits=4):
    """Markdown table: one row per order, one column per model, cells = row[key]."""
    models = list(dict.fromkeys(r["model"] for r in rows))
    orders = sorted({r["order"] for r in rows})
    cell = {(r["model"], r["order"]): r for r in rows}
    lines = ["| order | " + " | ".join(models) + " |", "| ---: | " + " | ".join("---:" for _ in models) + " |"]
    for order in orders:
        vals = [_fmt(cell[(mdl, order)][key], digits) if (mdl, order) in cell else "" for mdl in models]
        lines.append("| %d | %s |" % (order, " | ".join(vals)))
    return "\n".join(lines)


def long_markdown(rows):
    lines = ["| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    for row in rows:
        lines.append("| " + " | ".join(_fmt(row[k]) for k in COLUMNS) + " |")
    return "\n".join(lines)


def summary_markdown(rows, title, n_samples, noise):
    """The human-readable report: objective and RMS/noise pivots, then every row."""
    floor = "noise floor %s (rms, reference units), %s as a 2-norm" % (
        _fmt(noise), _fmt(noise * math.sqrt(n_samples)) if noise else "-"
    )
    parts = [
        "## %s" % title,
        "",
        "%d samples; %s." % (n_samples, floor),
        "",
        "Objective (residual 2-norm, the paper's Fig. 3a):",
        "",
        pivot_markdown(rows, "norm2"),
        "",
        "RMS / noise floor:",
        "",
        pivot_markdown(rows, "rms_over_noise", 3),
        "",
        "Parameters stored (n_params):",
        "",
        pivot_markdown(rows, "n_params"),
    ]
    return "\n".join(parts) + "\n"


def plot(rows, path, title, n_samples, noise=None):
    """PNG: objective vs order (the paper's Fig. 3a) and RMS vs n_params, log y, noise floor drawn."""
    from matplotlib.figure import Figure  # a figure of its own: matplotlib's backend stays as it is

    fig = Figure(figsize=(12, 4.8))
    ax1, ax2 = fig.subplots(1, 2)
    # models that coincide (pcm, pcm-raw and cheb are one polynomial) stay visible by style
    styles = [("o", "-"), ("s", "--"), ("^", ":"), ("v", "-."), ("D", "-"), ("x", "--"), ("+", ":"), ("*", "-.")]
    for i, name in enumerate(dict.fromkeys(r["model"] for r in rows)):
        mine = [r for r in rows if r["model"] == name and not math.isnan(r["norm2"])]
        if not mine:
            continue
        marker, line = styles[i % len(styles)]
        kw = dict(marker=marker, ls=line, ms=4, label=name)
        ax1.plot([r["order"] for r in mine], [r["norm2"] for r in mine], **kw)
        ax2.plot([r["n_params"] for r in mine], [r["rms"] for r in mine], **kw)
    if noise:
        ax1.axhline(noise * math.sqrt(n_samples), color="k", ls="--", lw=1, label="noise floor")
        ax2.axhline(noise, color="k", ls="--", lw=1, label="noise floor")
    ax1.set(xlabel="order n (degree, or knots/points)", ylabel="objective ||y - f(x)||_2", yscale="log")
    ax2.set(xlabel="parameters stored", ylabel="RMS residual (reference units)", yscale="log")
    for ax in (ax1, ax2):
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def write_outputs(rows, out_dir, stem, title, n_samples, noise):
    """Write STEM.csv, STEM.md and STEM.png into out_dir; returns the three paths."""
    out = Path(out_dir)
    os.makedirs(out, exist_ok=True)
    paths = (out / (stem + ".csv"), out / (stem + ".md"), out / (stem + ".png"))
    write_csv(rows, paths[0])
    md = summary_markdown(rows, title, n_samples, noise) + "\nAll rows:\n\n" + long_markdown(rows) + "\n"
    paths[1].write_text(md)
    plot(rows, paths[2], title, n_samples, noise)
    return paths
