"""Calibration 3 (SPEC section 4): force from spring deformation, F0(d) and its inverse d(F0).

The block pulls the force gauge through a fibre. Each round loads and unloads in open-loop duty
steps (the motor stalls against the fibre, so the duty sets the force without knowing the fibre's
stiffness); at each step, once still, the firmware's deformation d = D1* - D2 (Df-corrected, so
the assembly step must be done) and the gauge reading are averaged. The gauge is tared with the
fibre slack first. F0 = -gauge (pulling the block toward 0 mm is a negative actuator force).
Both directions are fitted from the same points (quadratics by default, `auto` = order by
cross-validation), and the loading/unloading hysteresis is reported.
"""

import numpy as np

from host.calibration_file import poly_section
from host.errors import UserError
from host.guided import acquire
from host.guided.assembly_calibration import choose_order
from host.guided.outcome import StepOutcome
from host.guided.prompts import end_progress, progress_line

D_RANGE_MM = (-2.0, 2.0)  # the cavity: |d| never exceeds 2 mm
F_RANGE_N = (-25.0, 25.0)


def _gauge(rig, reads):
    return float(np.mean([rig.gauge_reading_n() for _ in range(reads)]))


def force_points(session, rig, prompter, opts):
    """(d_mm, force_N, loading) arrays from `opts.rounds` loading/unloading rounds."""
    client = session.client
    anchor = opts.anchor_mm
    prompter.say("  moving the block to %.1f mm, where the fibre will hang slack" % (anchor + 1.5))
    ok, _ = acquire.hold(client, "position", int((anchor + 1.5) * 1000), "d2_um", 300, timeout_s=10)
    client.call("stop")
    if not ok:
        status = client.call("status")
        raise UserError("could not move the block to %.1f mm to hook the fibre slack (mode %s, faults %s)" % (
            anchor + 1.5, status.get("mode"), ", ".join(status.get("faults") or []) or "none"))
    rig.hook_gauge(anchor)
    prompter.say("  taring the gauge")
    tare = _gauge(rig, 3 if rig.virtual else 1)  # a person reads the tare once
    levels = np.linspace(0, opts.max_duty, opts.levels + 1)[1:]
    d, f, loading = [], [], []
    for r in range(opts.rounds):
        for load, seq in ((True, levels), (False, levels[::-1][1:])):
            for duty in seq:
                client.call("mode", "open_loop")
                client.call("target", -int(duty))
                acquire.collect(client, opts.settle_s)  # let it come to rest against the fibre
                rec = acquire.collect(client, 0.3)
                d.append(acquire.mean(rec, "defl_um") / 1000.0)
                f.append(-(_gauge(rig, 1) - tare))
                loading.append(load)
                progress_line("  round %d/%d %s duty %5d: d %+.3f mm, gauge %+.2f N" % (
                    r + 1, opts.rounds, "loading  " if load else "unloading", -duty, d[-1], -f[-1]))
        client.call("stop")
    end_progress()
    client.call("stop")
    return np.array(d), np.array(f), np.array(loading), tare


def hysteresis_n(d, f, loading, order):
    """Largest gap between loading and unloading fits of F0(d) over their common range (N)."""
    if np.count_nonzero(loading) <= order or np.count_nonzero(~loading) <= order:
        return float("nan")
    cl = np.polyfit(d[loading], f[loading], order)
    cu = np.polyfit(d[~loading], f[~loading], order)
    lo = max(d[loading].min(), d[~loading].min())
    hi = min(d[loading].max(), d[~loading].max())
    grid = np.linspace(lo, hi, 200)
    return float(np.max(np.abs(np.polyval(cl, grid) - np.polyval(cu, grid))))


def calibrate_force(session, rig, prompter, opts, calibration_path):
    from host.calibration_file import read_calibration

    doc = read_calibration(calibration_path) if calibration_path.exists() else {}
    if not doc.get("df"):
        raise UserError("the force step needs the assembly (Df) calibration first: host calibrate assembly")
    prompter.say("[force] %d loading/unloading rounds against the force gauge" % opts.rounds)
    d, f, loading, tare = force_points(session, rig, prompter, opts)
    taut = np.abs(f) > 0.3  # slack-fibre points say nothing about the spring
    if np.count_nonzero(taut) < 6:
        return StepOutcome("force", {}, ["force: the gauge never read a force (is the fibre hooked?)"], [], ok=False)
    dt, ft, lt = d[taut], f[taut], loading[taut]
    order_f, scores_f = choose_order(dt, ft, opts.force_order) if opts.force_order == "auto" else (int(opts.force_order), {})
    order_d, _ = choose_order(ft, dt, opts.force_order) if opts.force_order == "auto" else (int(opts.force_order), {})
    cf = np.polyfit(dt, ft, order_f)
    cd = np.polyfit(ft, dt, order_d)
    rf = ft - np.polyval(cf, dt)
    rd = dt - np.polyval(cd, ft)
    hyst = hysteresis_n(dt, ft, lt, order_f)
    lines = [
        "force: %d points (%d taut), gauge tare %.2f N, d %.3f..%.3f mm, F0 %.2f..%.2f N" % (
            len(d), len(dt), tare, dt.min(), dt.max(), ft.min(), ft.max()),
        "force: F0(d) = " + " + ".join("%.4g d^%d" % (c, order_f - i) for i, c in enumerate(cf)) +
        "  (N, mm; rms %.3f N, max %.3f N)" % (np.sqrt(np.mean(rf**2)), np.max(np.abs(rf))),
        "force: d(F0) = " + " + ".join("%.4g F^%d" % (c, order_d - i) for i, c in enumerate(cd)) +
        "  (mm, N; rms %.1f um, max %.1f um)" % (1000 * np.sqrt(np.mean(rd**2)), 1000 * np.max(np.abs(rd))),
        "force: loading/unloading hysteresis %.3f N (largest gap between the two fits)" % hyst,
    ]
    if scores_f:
        lines.append("force: cross-validated rms by order: " + ", ".join("%d: %.3f N" % kv for kv in scores_f.items()))
    stats_f = {"order": order_f, "rms_n": float(np.sqrt(np.mean(rf**2))), "hysteresis_n": hyst, "tare_n": tare}
    stats_d = {"order": order_d, "rms_mm": float(np.sqrt(np.mean(rd**2)))}
    sections = {
        "force": poly_section(cf, D_RANGE_MM, 1000.0, 1000.0, ("um", "mN"), stats_f),
        "force_inverse": poly_section(cd, F_RANGE_N, 1000.0, 1000.0, ("mN", "um"), stats_d),
    }
    png = opts.out_dir / "calibration-force.png"
    plot_force(png, d, f, loading, cf)
    data = {"d_mm": d, "force_n": f, "loading": loading, "coeffs_f": cf, "coeffs_d": cd, "hysteresis_n": hyst}
    return StepOutcome("force", sections, lines, [png], ok=True, data=data)


def plot_force(path, d, f, loading, cf):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    ax.plot(d[loading], f[loading], "v", color="tab:red", ms=4, label="loading")
    ax.plot(d[~loading], f[~loading], "^", color="tab:blue", ms=4, label="unloading")
    grid = np.linspace(np.min(d), np.max(d), 200)
    ax.plot(grid, np.polyval(cf, grid), "k-", lw=1, label="F0(d), order %d" % (len(cf) - 1))
    ax.set_xlabel("spring deformation d = D1* - D2 (mm)")
    ax.set_ylabel("actuator force F0 = -gauge (N)")
    ax.set_title("Force identification (paper eqs. 8-9)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
