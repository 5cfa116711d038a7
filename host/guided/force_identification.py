"""What the force step's points say (the paper's section 4 with the block's friction): F0(d), its
inverse and the friction h fitted (`identify`, host/fitting/force.py underneath), the stalled
motor's force per duty and the feed-forward duty (`fit_drive`), the calibration sections they
make (`force_sections`), the forces a side can use before the spring's hard contact
(`usable_range`), whether the gauge followed the spring at all (`check_gauge_follows`), and the
plot. host/guided/force_calibration.py measures the points on the bench; the offline bench and
the friction trim fit them here too.
"""

from dataclasses import dataclass

import numpy as np

from firmware.calibration import FF_DUTY_MAX
from host.calibration.file import force_table_section, friction_section, poly_section
from host.errors import UserError
from host.fitting.force import fit_force

D_RANGE_MM = (-2.0, 2.0)  # the cavity: |d| never exceeds 2 mm
F_RANGE_N = (-25.0, 25.0)
TAUT_N = 0.3  # below this the fibre may be slack: such points say nothing about the spring
SIDES = {"high": -1, "low": 1}  # gauge side -> sign of the actuator's force against it


MIN_CORRELATION = 0.9  # the gauge's force against the spring's deformation over a side's points
MIN_SPAN_N = 0.5  # and it must move at least this much while the spring deforms MIN_SPAN_MM
MIN_SPAN_MM = 0.1


def check_gauge_follows(d, forces, side):
    """UserError unless the gauge's readings on `side` move with the spring's deformation: a
    gauge not hooked, or read from an input it is not wired to (--gauge adc on a board without
    it), gives readings that stay flat or wander, and F0 fitted to them would be nonsense. The
    force and the deformation rise and fall together on a spring, friction or not."""
    d, forces = np.asarray(d, dtype=float), np.asarray(forces, dtype=float)
    if len(d) < 3 or np.ptp(d) < MIN_SPAN_MM:
        return  # too little motion to judge (the step's own checks say so)
    r = float(np.corrcoef(d, forces)[0, 1]) if np.ptp(forces) > 0 else 0.0
    if np.ptp(forces) < MIN_SPAN_N or not r >= MIN_CORRELATION:
        raise UserError("gauge on the %s side: its readings do not follow the spring (deformation %.3f..%.3f mm, gauge "
                        "%.2f..%.2f N, correlation %.2f): is the gauge hooked to the block, and read from where it is "
                        "wired (--gauge display or adc)?" % (side, d.min(), d.max(), forces.min(), forces.max(), r))


@dataclass
class Drive:
    n_per_duty: float  # force the stalled motor holds per duty count, N
    offset_n: float  # force at zero duty by the straight line (negative: the screw's own friction)
    ff_duty: int  # the duty that holds the spring at the block's friction force (0: none)
    why: str = ""


def fit_drive(duty, spring_n, friction_n):
    """The stalled motor's force per duty, from the force step's points (at each one the motor
    holds the spring still, so its force is the spring's), and the duty that holds the spring at
    the friction force: (h - min(offset, 0)) / slope (a negative offset is force the screw's own
    friction takes before the spring gets any; a positive one is not counted on)."""
    duty = np.abs(np.asarray(duty, dtype=float))
    force = np.abs(np.asarray(spring_n, dtype=float))
    if len(duty) < 3 or np.ptp(duty) <= 0:
        return Drive(0.0, 0.0, 0, "too few duty levels")
    slope, offset = np.polyfit(duty, force, 1)
    if not slope > 0:
        return Drive(float(slope), float(offset), 0, "the force did not grow with the duty")
    if friction_n <= 0:
        return Drive(float(slope), float(offset), 0, "no friction identified")
    ff = int(round((friction_n - min(offset, 0.0)) / slope))
    if not 0 < ff <= FF_DUTY_MAX:
        return Drive(float(slope), float(offset), 0, "%d duty is outside 1..%d" % (ff, FF_DUTY_MAX))
    return Drive(float(slope), float(offset), ff)


def poly_text(c, var):
    n = len(c) - 1
    return " + ".join("%.4g %s^%d" % (v, var, n - i) for i, v in enumerate(c))


def identify(d, f, s, loading, duty, order="auto", friction=True):
    """The force step's fit of its taut points, in the order taken: (ForceFit, Drive, a note or
    None). A table the firmware cannot hold gives way to the next simpler model: a spring
    spline's to the free-knot table or polynomial the fit would have kept without it, a free-knot
    table to the polynomial it beat (the note says so); the drive is fitted on the points at the
    band's edge (not ForceFit.left_out)."""
    unexported = fit = None
    for tables, spline in ((True, True), (True, False), (False, False)):
        if unexported and tables and not spline and fit.kinks_mm is None:
            continue  # the refused table was no spline's: the same free-knot table would come again
        fit = fit_force(d, f, s, order, friction=friction, tables=tables, loading=loading, spline=spline)
        if fit.kind != "pwl":
            break
        try:
            force_table_section(fit.knots_d, fit.knots_f, D_RANGE_MM, ("um", "mN"))
            force_table_section(fit.knots_f, fit.knots_d, F_RANGE_N, ("mN", "um"))
            break
        except UserError as exc:
            what = "spline's table" if fit.kinks_mm is not None else "table"
            unexported = "force: the %s cannot be exported (%s): a simpler F0 is kept" % (what, exc)
    on_edge = ~fit.left_out
    drive = fit_drive(duty[on_edge], (f - fit.friction_n * s)[on_edge], fit.friction_n)
    return fit, drive, unexported


def force_sections(fit, drive, stats_f=None):
    """The calibration sections `force`, `force_inverse` and `friction` of a fit (identify)."""
    stats_d = {"order": fit.order_d, "rms_mm": fit.rms_d_mm}
    table = fit.kind == "pwl"
    return {
        "force": force_table_section(fit.knots_d, fit.knots_f, D_RANGE_MM, ("um", "mN"), stats_f) if table else
        poly_section(fit.coeffs_f, D_RANGE_MM, 1000.0, 1000.0, ("um", "mN"), stats_f),
        "force_inverse": force_table_section(fit.knots_f, fit.knots_d, F_RANGE_N, ("mN", "um"), stats_d) if table else
        poly_section(fit.coeffs_d, F_RANGE_N, 1000.0, 1000.0, ("mN", "um"), stats_d),
        # always written, so that a --no-friction run also replaces an older friction section
        "friction": friction_section(fit.friction_n, {"rms_n": fit.rms_n, "points": int(np.count_nonzero(~fit.left_out)),
                                                      "n_per_kduty": 1000 * drive.n_per_duty, "offset_n": drive.offset_n},
                                     ff_duty=drive.ff_duty),
    }


CONTACT_COMPLIANCE = 0.8  # a loading level that deforms the spring this much less per newton than the one before: contact


def usable_range(d, f, loading, duty, side, friction_n=0.0):
    """(the largest force magnitude the force step measured on `side`, the largest before the
    spring went into hard contact, the force where it did or None), N.

    A spring pair deforms more per newton once a preloaded spring lifts off, and a little less as
    it hardens, but when the nut meets the cavity's wall the deformation stops growing with the
    force: the loading levels' compliance (mm per N between successive duty levels, the rounds
    averaged) falls. A level whose compliance is under CONTACT_COMPLIANCE times the one before
    was reached through contact; there F0(d) is not the spring's, and the trim's holds and the
    experiments' forces stay below it. The first segment is not judged: at its small forces the
    fibre's take-up and the friction band make its compliance what they please (2.1 -> 3.6 N
    deformed 45 % more per newton than the rest on one actuator). Nor is any segment that starts
    within the friction band (2 x `friction_n`) of the first level, nor compared against: on a
    block with 1.19 N of friction the 2.2 -> 3.1 N segment deformed 60 % more per newton than
    the rest, and the next, an ordinary one, read as contact at 3.1 N (seed 202611270601)."""
    sign = SIDES[side]
    on = (sign * np.asarray(f) > TAUT_N) & np.asarray(loading, dtype=bool)
    if not np.any(sign * np.asarray(f) > 0):
        return 0.0, 0.0, None
    reached = float(np.max(sign * np.asarray(f)))
    levels = sorted({int(abs(x)) for x in np.asarray(duty)[on]})
    pts = []
    for level in levels:
        at = on & (np.abs(np.asarray(duty)).astype(int) == level)
        pts.append((float(np.mean(sign * np.asarray(d)[at])), float(np.mean(sign * np.asarray(f)[at]))))
    compliance = [(b[0] - a[0]) / (b[1] - a[1]) if b[1] > a[1] else 0.0 for a, b in zip(pts, pts[1:])]
    # the first segment compared against: not the first (the fibre and the friction band still
    # settle there), nor one that starts inside the band
    first = next((i for i in range(1, len(compliance)) if pts[i][1] >= pts[0][1] + 2.0 * friction_n), len(compliance))
    for i in range(first + 1, len(compliance)):
        if compliance[i] < CONTACT_COMPLIANCE * compliance[i - 1]:
            return reached, pts[i][1], pts[i + 1][1]
    return reached, reached, None


def plot_force(path, d, f, s, fit, inside=None):
    from matplotlib.figure import Figure  # drawn and written without pyplot: no backend is chosen

    fig = Figure(figsize=(7, 6.5))
    ax, ax2 = fig.subplots(2, 1, sharex=True, gridspec_kw={"height_ratios": [3, 1.3]})
    inside = np.zeros(len(d), dtype=bool) if inside is None else inside
    down = (s > 0) & ~inside
    up = (s <= 0) & ~inside
    ax.plot(d[down], f[down], "v", color="tab:red", ms=4, label="force fell (block slid toward 0 mm)")
    ax.plot(d[up], f[up], "^", color="tab:blue", ms=4, label="force rose (block slid toward 60 mm)")
    if np.any(inside):
        ax.plot(d[inside], f[inside], "o", mfc="none", color="0.3", ms=5,
                label="just after a turn or a round's start, inside the band (left out)")
    grid = np.linspace(np.min(d), np.max(d), 200)
    spring = fit.f0(grid)
    ax.plot(grid, spring, "k-", lw=1, label="F0(d), %s (spring)" % (
        "order %d" % fit.order_f if fit.kind == "poly" else "%d-knot table" % len(fit.knots_d) if fit.kinks_mm is None
        else "spline, kinks at %s mm" % (", ".join("%.2f" % r for r in fit.kinks_mm) or "none")))
    if fit.friction_n > 0:
        ax.fill_between(grid, spring - fit.friction_n, spring + fit.friction_n, color="0.8", alpha=0.6,
                        label="friction band +-%.2f N" % fit.friction_n)
    ax.set_ylabel("actuator force = gauge (N)")
    ax.set_title("Force identification (paper eqs. 8-9, with the block's friction)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    resid = f - fit.f0(d) - fit.friction_n * s
    ax2.plot(d[~inside], resid[~inside] * 1000, ".", color="tab:green", ms=4)
    ax2.plot(d[inside], resid[inside] * 1000, "o", mfc="none", color="0.3", ms=4)
    ax2.axhline(0, color="0.5", lw=0.6)
    ax2.set_xlabel("spring deformation d = D1* - D2 (mm)")
    ax2.set_ylabel("residual (mN)")
    ax2.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return path
