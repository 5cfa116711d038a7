"""The Markdown report of `host experiment paper`: each measured figure beside the paper's.

Everything written here comes from the `results` dict of the run (no stored numbers except the
paper's, quoted from the paper's section 5 (Song et al., Actuators 2022), and the project's targets for the simulated
actuator). The report states what was simulated and where the run was shortened.
"""

import datetime
import math
import sys
from pathlib import Path

import numpy as np

from host.experiments import displacement, held_out, model_compare
from host.experiments.targets import headline, judged
from host.guided.stroke import DEFAULT_MM  # a run's results without a stroke: the 0-60 mm actuator's

def _met(ok):
    return "met" if ok else "**NOT met**"


def _df_model(fig5):
    """'order 7' for a polynomial Df, '14-knot table' for a table."""
    return ("%d-knot table" if fig5.get("model") == "table" else "order %d") % fig5["order"]


def _f(v, digits=3):
    return "-" if v is None or (isinstance(v, float) and math.isnan(v)) else ("%.*f" % (digits, v))


def _what_was_simulated(r):
    """Which board ran the firmware, and what stood in for the actuator and the rig."""
    if r.get("chip") == "rp2040":
        interpreter = r.get("interpreter") or "micropython"
        runtime = ("CircuitPython's own build for the Pico" if interpreter.startswith("circuitpython")
                   else "MicroPython's own rp2 port")
        board = ("The board is an emulated Raspberry Pi Pico (`--port sim:rp2040`): %s (%s, "
                 "the firmware a user flashes onto a Pico) on the rp2040js emulator of the RP2040, one Cortex-M0+ core "
                 "in emulated time, with the real firmware installed by `host flash` over its emulated USB serial. Its "
                 "ADC inputs read, and its PWM slices drive, the physical model in `boards/sim/` wired to the pins of "
                 "boards/%s.json, advanced in lockstep with the chip (host/link/emulated_pico/)"
                 % (runtime, interpreter, r.get("board") or "pico"))
        rig = "is applied to the model directly by the emulated Pico's bench process"
    else:
        board = ("The board is the real firmware on the MicroPython unix port behind a pty (`--port sim`); ADC, PWM "
                 "and timer are the physical model in `boards/sim/`")
        rig = "is applied by `boards/sim/bench_rig.py`"
    return ("**What was simulated.** %s (motor, lead screw, preloaded hardening springs, block with Coulomb friction "
            "and end stops, two knee-shaped pots with a mounting error, a reference sensor mounted in parallel with a "
            "pot, and a force gauge on a fibre whose zero drifts; docs/simulated-actuator.md). The bench rig (which pot "
            "carries the reference, the gauge hooked or not) %s. None of this is the paper's hardware: the comparison "
            "shows whether the method reproduces the paper's effects, not the paper's actuator." % (board, rig))


def write(out_dir, r, opts, command=None):
    """DIR/report.md from the run's results `r`: one section each, in the paper's order."""
    out_dir = Path(out_dir)
    command = command or "host " + " ".join(sys.argv[1:]) if sys.argv[1:] else "host experiment paper"
    lines = []
    add = lines.append
    _head_section(add, r, opts, command)
    for section in (_summary_section, _calibration_section, _fig3a_section, _fig5_section, _fig7_section,
                    _fig8_section, _dead_zone_section, _table1_section, _held_out_section):
        section(add, r)
    path = out_dir / "report.md"
    path.write_text("\n".join(lines) + "\n")
    return path


def _head_section(add, r, opts, command):
    """Title, when and how it was made, what was simulated, what was shortened, the method."""
    sim = r["simulated"]
    where = ("the simulated actuator (virtual board)" if not r.get("chip") else
             "the simulated actuator on an emulated %s (board %s)" % ({"rp2040": "Raspberry Pi Pico"}.get(r["chip"], r["chip"]), r["board"]))
    add("# The paper's experiments, measured on %s" % (where if sim else "board " + r["board"]))
    add("")
    add("Made by `%s` on %s in %.0f s of wall time. Every number below was measured in that run; "
        "the paper's numbers are quoted from the paper's section 5." % (
            command, datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"), r["timings"]["total"]))
    add("")
    if sim:
        add(_what_was_simulated(r))
        add("")
    m0 = r.get("method", {})
    add("**Shortened from the paper** (to keep the run to a few minutes): %d force identification rounds per gauge "
        "side (paper 5), %d displacement targets (%s mm; the paper's run to 60 mm, the firmware's soft stroke limits "
        "at %s and %s mm keep the block off the end stops), one sweep per pot." % (
            m0.get("rounds", getattr(opts, "rounds", 0)), len(r["fig7"]["after"]), ", ".join("%g" % t["target"] for t in r["fig7"]["after"]),
            _f(r.get("stroke_mm", (None, None))[0], 1), _f(r.get("stroke_mm", (None, None))[1], 1)))
    add("")
    m = r.get("method", {})
    add("**Method.** Pot model: %s -> pot 1 %s, pot 2 %s. Df order: %s -> %s. Force: order %s -> %s, gauge side(s) %s, "
        "block friction %s. (`--paper-method` runs the paper's choices: BCM-3, quartic Df, quadratic force fits "
        "without friction, gauge on the 60 mm side.) Timings: %s." % (
            r["model"], r["pot_models"]["pot1"], r["pot_models"]["pot2"], m.get("df_order"), _df_model(r["fig5"]),
            m.get("force_order"), m.get("force_order_chosen", "-"),
            m.get("gauge_sides"), "identified and compensated" if m.get("friction") else "not modelled",
            ", ".join("%s %.0f s" % kv for kv in r["timings"].items())))
    add("")



def _summary_section(add, r):
    """Every figure beside the paper's and its target, judged."""
    h = headline(r)
    before, after, fig5, t1 = h["before"], h["after"], r["fig5"], r["table1"]
    worst_ss, worst_est, paper_rows = h["worst_steady_pct"], h["worst_estimation_pct"], h["paper_rows"]
    without, with_df, no_block = h["without_df"], h["with_df"], h["no_blocking"]
    rows3 = r["fig3a"]
    bcm3 = model_compare.norm_at(rows3, "bcm", 3)
    match = model_compare.pcm_order_matching(rows3, bcm3)
    add("## Summary")
    add("")
    add("| experiment | paper | this run | target (simulated actuator) |")
    add("| --- | --- | --- | --- |")
    add("| BCM vs PCM (Fig. 3a) | BCM-3 ~ PCM-10 | BCM-3 objective %s; PCM needs order %s to match | - |" % (
        _f(bcm3, 2), match if match else "> %d" % max(x["order"] for x in rows3)))
    ok = judged(h, r)
    lo, hi = r.get("stroke_nominal_mm") or DEFAULT_MM
    span = "%g-%g" % (min(x["target"] for x in r["fig7"]["after"]), max(x["target"] for x in r["fig7"]["after"])) if r["fig7"]["after"] else "-"
    hdf, hpos = h["held_out_df_mm"], h["held_out_displacement_mm"]
    add("| Df calibration (Fig. 5) | peak 4.9 -> 0.9 mm (-81.6 %%) | peak %s -> %s mm of 1 mm bin means on the sweep it "
        "was fitted to (%+.1f %%; %s; %s mm of single samples); **held out: %s mm** on a validation sweep | <= 0.1 mm "
        "(bin means, %s): %s |" % (
            _f(fig5["peak_before_mm"], 2), _f(fig5["peak_after_binned_mm"], 3),
            100 * (fig5["peak_after_binned_mm"] / fig5["peak_before_mm"] - 1), _df_model(fig5), _f(fig5["peak_after_mm"], 3),
            _f(hdf, 3), "held out" if hdf is not None else "in-sample", _met(ok["Df"])))
    add("| displacement control (Fig. 7), max error %s mm | 14.4 -> 4.2 mm (-70.8 %%) | %s -> %s mm (%+.1f %%) at the "
        "paper's targets; **held out: %s mm** at %d drawn ones | <= 0.1 mm (%s): %s |" % (
            span, _f(before), _f(after), 100 * (after / before - 1), _f(hpos), len((r.get("held_out") or {}).get("positions") or []),
            "both" if hpos is not None else "paper's targets", _met(ok["displacement"])))
    add("| force control 5 N at no load from %g mm (Fig. 8) | blocks at 43.1 mm without Df; runs to 60 mm with | "
        "without Df ends at %s mm; with Df ends at %s | no blocking at +-1 to 10 N: %s |" % (
            (lo + hi) / 2, _f(without[0]["final"], 1) if without else "-",
            ", ".join("%s mm (%+.0f N)" % (_f(b["final"], 1), b["target_n"]) for b in with_df), _met(no_block)))
    add("| force dead zone (0-5 N, 0.2 N steps) | about 0.4 N | %s N | - |" % _f(r["dead_zone"]["dead_zone_n"], 1))
    kinds = "%s, loading and unloading" % ("both signs" if len({x.get("side", "high") for x in t1}) > 1 else "one sign")
    hss, hest = h["held_out_steady_pct"], h["held_out_estimation_pct"]
    held_n = len((r.get("held_out") or {}).get("forces") or [])
    judged_on = "held out" if hss is not None else "the paper's steps"
    add("| force steps -5/-10/-15 N (Table 1), steady-state error | -4.6 / -7.0 / 4.0 %% | %s %%; worst of all %d steps "
        "(%s; next to where the calibration's trim held) %s %%; **held out: worst %s %%** of %d steps at drawn forces | "
        "<= 2 %% (%s): %s |" % (
            " / ".join("%+.1f" % x["steady_pct"] for x in paper_rows) or "-", len(t1), kinds, _f(worst_ss, 1), _f(hss, 1), held_n,
            judged_on, _met(ok["force steps"])))
    add("| same, estimation error | -2.5 / -5.6 / 2.8 %% | %s %%; worst of all %d steps %s %%; **held out: worst %s %%** | "
        "<= 2 %% (%s, with the steady-state error) |" % (
            " / ".join("%+.1f" % x["estimation_pct"] for x in paper_rows) or "-", len(t1), _f(worst_est, 1), _f(hest, 1),
            judged_on))
    away = (r.get("held_out") or {}).get("away") or {}
    if away:
        add("| force steps away from the calibration's position (the paper's Table 1 ran at mid stroke) | - | gauge at "
            "D2 = %g mm, the force calibration's at %g mm: **held out: worst %s %% steady-state, %s %% estimation** of %d "
            "steps at drawn forces | <= 2 %% (held out): %s |" % (
                away["anchor_mm"], away["calibrated_at_mm"], _f(h["away_steady_pct"], 1), _f(h["away_estimation_pct"], 1),
                len(away.get("forces") or []), _met(ok["force elsewhere"])))
    add("")
    off = r.get("paper_method_offline")
    if off:
        add("The paper's fits on this run's own sweeps: BCM-3 leaves pot 1 rms %s / max %s mm and pot 2 rms %s / max %s mm "
            "(the chosen pot curves: see Calibration); a quartic Df leaves a %s mm peak of 1 mm bin means (%s here: %s mm); "
            "a quadratic F0(d) without the friction term on the 60 mm side's points leaves rms %s N (this run's F0: %s N)." % (
                _f(off["pot1"]["rms_mm"]), _f(off["pot1"]["max_mm"]), _f(off["pot2"]["rms_mm"]), _f(off["pot2"]["max_mm"]),
                _f(off["df4_binned_mm"]), _df_model(fig5), _f(fig5["peak_after_binned_mm"]),
                _f(off.get("force2_rms_n")), _f(r["force_fit"].get("rms_n"))))
        add("")



def _calibration_section(add, r):
    add("## Calibration (host calibrate, logged in this run)")
    add("")
    for step, lines in r["calibration"].items():
        add("**%s**" % step)
        add("")
        for line in lines:
            add("- " + line)
        add("")
    for name in r["calibration_plots"]:
        add("![%s](%s)" % (name, name))
    add("")
    ff = r["force_fit"]
    if ff.get("kinks_mm") is not None:
        model = ("a cubic spline with a kink where a spring lifts off its preload (kinks at d = %s mm), tabulated in %d "
                 "knots (cross-validation scored it within 5 %% of the best free-knot table, or 10 %% better than the "
                 "polynomial; the best polynomial: F0 = %s)" % (
                     ", ".join("%.2f" % r for r in ff["kinks_mm"]) or "none", len(ff["knots_d"]), _poly(ff["coeffs_f"], "d")))
    elif ff.get("kind") == "pwl":
        model = ("a %d-knot table through (d mm, F0 N) %s, its inverse d(F0) the same knots (the spring's stiffness "
                 "changes where a preloaded spring lifts off: a polynomial's cross-validated error was over %.0f %% "
                 "higher; the best polynomial: F0 = %s)" % (
                     len(ff["knots_d"]), ", ".join("(%.3f, %.2f)" % kv for kv in zip(ff["knots_d"], ff["knots_f"])),
                     100 * (1 / 0.8 - 1), _poly(ff["coeffs_f"], "d")))
    else:
        model = "%s (N, d in mm); d(F0) = %s (mm, F0 in N)" % (_poly(ff["coeffs_f"], "d"), _poly(ff["coeffs_d"], "F0"))
    add("Force fit: F0(d) = %s; block friction %s N; loading/unloading hysteresis %s N. Paper (reconstructed): "
        "F0 ~ 0.65 d^2 + 12.37 d + 2.08, d ~ 0.00091 F0^2 + 0.070 F0 - 0.18." % (
            model, _f(ff.get("friction_n")), _f(ff["hysteresis_n"])))
    add("")



def _fig3a_section(add, r):
    rows3 = r["fig3a"]
    bcm3 = model_compare.norm_at(rows3, "bcm", 3)
    add("## Fig. 3a: objective vs order (pot 2 sweep of this run)")
    add("")
    add("Paper: a 3rd-order BCM matches about a 10th-order PCM. Here: BCM-3 objective %s, PCM orders: %s." % (
        _f(bcm3, 2), ", ".join("%d: %s" % (x["order"], _f(x["norm2"], 2)) for x in rows3 if x["model"] == "pcm")))
    add("Full tables: [fig3a.md](fig3a.md), [fig3a.csv](fig3a.csv).")
    add("")
    add("![Fig. 3a](fig3a.png)")
    add("")


def _fig5_section(add, r):
    fig5 = r["fig5"]
    add("## Fig. 5: assembly error Df before and after")
    add("")
    add("%s; peak |Df| %s mm before; after, peak residual %s mm of the means over 1 mm of D1 (the "
        "curve's error) and %s mm of single samples (that includes the noise of two pot readings), rms %s mm; %d samples. "
        "Paper: 4.9 -> 0.9 mm." % (_df_model(fig5).capitalize(), _f(fig5["peak_before_mm"]), _f(fig5["peak_after_binned_mm"]),
                                   _f(fig5["peak_after_mm"]), _f(fig5["rms_after_mm"]), fig5["n_samples"]))
    add("")
    add("![Fig. 5](calibration-df.png)")
    add("")


def _fig7_section(add, r):
    h = headline(r)
    before, after = h["before"], h["after"]
    add("## Fig. 7: displacement control, error measured by the reference sensor on pot 2")
    add("")
    add("| target mm | before: reference mm | before: error mm | after: reference mm | after: error mm | after: settle time s |")
    add("| --- | --- | --- | --- | --- | --- |")
    for b, a in zip(r["fig7"]["before"], r["fig7"]["after"]):
        add("| %g | %s | %s%s | %s | %s%s | %s |" % (b["target"], _f(b["reference"]), _f(b["error"]), "" if b["settled"] else " (not settled)",
                                                  _f(a["reference"]), _f(a["error"]), "" if a["settled"] else " (not settled)",
                                                  _f(a.get("settle_s"), 2)))
    add("")
    zero = r["fig7"].get("reference_zero")
    lo, hi = r.get("stroke_nominal_mm") or DEFAULT_MM
    add("Max |error| over %s mm: %s mm before, %s mm after. Paper: 14.4 -> 4.2 mm. The reference sensor measures "
        "pot 2's wiper travel (as on the paper's rig), so pot 2's mounting error is not in these errors. Positions are "
        "measured from the block's end stops, whose middle is %g mm, by the calibration and by this experiment alike%s. "
        "Settled: the 0.1 s mean of the firmware's D2 within 0.05 mm of the target for 0.2 s; the settle time runs from "
        "the command (the block starts at the previous target) until then." % (
            "%g-%g" % (min(x["target"] for x in r["fig7"]["after"]), max(x["target"] for x in r["fig7"]["after"])), _f(before), _f(after), (lo + hi) / 2, "" if not zero else " (the reference read %s and %s mm at the stops here)" % (
                _f(zero["low"]), _f(zero["high"]))))
    add("")
    add("![Fig. 7](fig7.png)")
    add("")


def _fig8_section(add, r):
    lo, hi = r.get("stroke_nominal_mm") or DEFAULT_MM
    blocking = r["fig8"]
    add("## Fig. 8: force control at no load from D2 = %g mm" % ((lo + hi) / 2))
    add("")
    add("| run | target N | D2 at the end mm |")
    add("| --- | --- | --- |")
    for name, b in blocking:
        add("| %s | %+.0f | %s |" % (name, b["target_n"], _f(b["final"], 2) if name != "not run" else
                                     "- (beyond the force range the calibration held: the board refuses it)"))
    add("")
    add("Without the Df correction the firmware's deformation includes Df(D1), which reaches the 5 N target deformation "
        "part-way, and the block stops there (paper: 43.1 mm). With it a free block under a positive force target runs "
        "on toward the %g mm end and one under a negative target toward %g mm, where the firmware's soft stroke limits "
        "(%s and %s mm) stop it; a block that ends elsewhere, or at the wrong end, blocked." % (
            hi, lo, _f(r.get("stroke_mm", (None, None))[0], 1), _f(r.get("stroke_mm", (None, None))[1], 1)))
    add("")
    add("![Fig. 8](fig8.png)")
    add("")


def _dead_zone_section(add, r):
    add("## Force dead zone")
    add("")
    add("Gauge hooked with the fibre just slack; force targets 0 to -5 N in 0.2 N steps, each held 0.5 s. Dead zone = the "
        "largest |target| whose measured |force| stays below half of it: **%s N** (paper: about 0.4 N)." % _f(r["dead_zone"]["dead_zone_n"], 1))
    add("")
    add("| target N | gauge N | firmware estimate N |")
    add("| --- | --- | --- |")
    for x in r["dead_zone"]["rows"]:
        add("| %+.1f | %s | %s |" % (x["target"], _f(x["measured"], 2), _f(x["estimate"], 2)))
    add("")


def _table1_section(add, r):
    t1 = r["table1"]
    m = r.get("method", {})
    add("## Table 1: force steps against the gauge")
    add("")
    add("| gauge side | phase | target N | gauge N | steady-state error % | estimate N | estimation error % | paper: measured / estimated N |")
    add("| --- | --- | --- | --- | --- | --- | --- | --- |")
    paper = {-5.0: "-5.2 / -5.1", -10.0: "-10.7 / -10.1", -15.0: "-14.4 / -14.8"}
    for x in t1:
        first = x.get("side", "high") == "high" and x.get("phase", "loading") == "loading"
        phase = x.get("phase", "loading")
        if not x.get("in_range", True):
            phase += " (beyond %.0f %% of the %.1f N the force step reached on this side)" % (100 * 0.9, x["reached_n"])
        add("| %s | %s | %+.0f | %s | %+.2f | %s | %+.2f | %s |" % (
            "60 mm" if x.get("side", "high") == "high" else "0 mm", phase, x["target"],
            _f(x["measured"], 2), x["steady_pct"], _f(x["estimate"], 2), x["estimation_pct"],
            paper.get(x["target"], "-") if first else "-"))
    add("")
    beyond = [x for x in t1 if not x.get("in_range", True)]
    if beyond:
        add("**Near the end of the calibrated range:** %s N lie beyond 90 %% of the force the force step measured on "
            "their side: F0 there is the last stretch of what it was measured over. They are reported, not judged "
            "(the targets are judged on held-out forces within 15-90 %% of each side's range)."
            % ", ".join("%+.0f" % x["target"] for x in beyond))
        add("")
    refused = r.get("table1_refused") or []
    if refused:
        add("**Not run:** %s: beyond the force the force step held on that side, which the board refuses as a "
            "target (the calibration's force range): the spring and motor were not shown to hold it."
            % "; ".join("%+.0f N (%s side, held %.2f N)" % (x["target"], "60 mm" if x["side"] == "high" else "0 mm",
                                                           x["reached_n"]) for x in refused))
        add("")
    add("Steady-state error = (gauge - target) / |target|; estimation error = (firmware estimate - gauge) / |gauge|. "
        "The gauge was tared with the fibre slack before and after each sequence (readings against the tare "
        "interpolated in time: its zero drifts), and a %.1f N preload took up the fibre's slack before the first "
        "step. The block slides on its slider between "
        "the spring and the fibre: its Coulomb friction%s makes the "
        "gauge read the spring force minus the friction in the direction the block last slid. %s" % (
            r.get("preload_n", 0.0),
            " (%s N in the simulated actuator's file, %.0f %% of 5 N)" % (_f(r["sim_block_friction_n"], 2), 20 * r["sim_block_friction_n"])
            if r.get("sim_block_friction_n") is not None else "",
            "The force calibration identified it (%s N) and the firmware compensates it: its estimate is the spring "
            "force through a play operator of that width, and the loop ramps the spring to the edge of the band "
            "from which the load's force reaches the target, then parks it in the band's middle "
            "(firmware/measurement.py, firmware/controller.py)." % _f(r["force_fit"].get("friction_n"))
            if m.get("friction") else "This run did not model it (--no-friction), so it shows in both errors."))
    add("")


def _held_out_section(add, r):
    ho = r.get("held_out")
    if not ho:
        return
    add("## Held out: what the calibration never saw")
    add("")
    add("Drawn for this run with seed %d (`--held-out-seed %d` repeats them); the targets are judged on these "
        "(host/experiments/held_out.py)." % (ho["seed"], ho["seed"]))
    add("")
    df = ho.get("df") or {}
    if df:
        add("**Df on a validation sweep** (no load, duty %s, the calibration on the board; the firmware's own D1* - D2 "
            "in 1 mm bins of D1, each direction's mean apart, the two averaged): peak **%s mm**; both directions pooled %s "
            "mm; single samples %s mm, rms %s mm, %s samples; the block's friction deflected the spring by %s mm either "
            "way. The fit's own residual was %s mm. The firmware's deformation at no load (D1* - D2 less the gain step's "
            "offset table, times its gain; binned the same way): peak %s mm." % (
                df.get("duty"), _f(df.get("peak_binned_mm")), _f(df.get("peak_pooled_mm")), _f(df.get("peak_single_mm")),
                _f(df.get("rms_mm")), df.get("n_samples"), _f(df.get("friction_deflection_mm")),
                _f(r["fig5"].get("peak_after_binned_mm")), _f(df.get("peak_deformation_mm"))))
        add("")
    pos = ho.get("positions") or []
    if pos:
        add("**Positions at drawn targets** (held and measured as Fig. 7's): max |error| **%s mm**." % _f(displacement.max_error(pos)))
        add("")
        add("| target mm | reference mm | error mm | settled |")
        add("| --- | --- | --- | --- |")
        for x in pos:
            add("| %g | %s | %s | %s |" % (x["target"], _f(x["reference"]), _f(x["error"]), "yes" if x["settled"] else "no"))
        add("")
    forces = ho.get("forces") or []
    draws = ho.get("force_draws") or {}
    if draws:
        add("**Force steps at drawn forces**: on each side 3 loading forces from 15-90 %% of the range the force step "
            "reached, then 3 unloading ones below the highest, at least 0.5 N from the forces the trim and its F0 check held and the "
            "paper's 5/10/15 N and 0.25 N from the force step's levels: %s." % "; ".join(
                "%s side reached %s N, the trim and its check held %s N" % (side, _f(d["reached_n"], 1), ", ".join("%g" % v for v in d["held_by_calibration_n"]) or "none")
                for side, d in draws.items()))
        add("")
    _force_table(add, forces)
    away = ho.get("away") or {}
    if away:
        add("**Force steps away from the calibration's position**: the gauge hooked at D2 = %g mm, the force step and "
            "its trim held it at %g mm. Under load the firmware's D1* - D2 is what Df left at no load plus the true "
            "deformation times the slope of pot 2's calibrated curve where the block is (pot 2's mounting error stays in "
            "its calibration: the reference reads the wiper), so F0 measured at one place holds elsewhere only as well "
            "as the gain step's offset and gain tables take those out (%s); these steps say how well. On each side %d "
            "loading and %d unloading forces drawn as above." % (
                away["anchor_mm"], away["calibrated_at_mm"],
                "in this calibration" if r.get("calibration", {}).get("gain") else "not in this calibration",
                held_out.AWAY_LOADING, held_out.AWAY_UNLOADING))
        add("")
        _force_table(add, away.get("forces") or [])


def _force_table(add, rows):
    if not rows:
        return
    add("| gauge side | phase | target N | gauge N | steady-state error % | estimate N | estimation error % |")
    add("| --- | --- | --- | --- | --- | --- | --- |")
    for x in rows:
        add("| %s | %s | %+.2f | %s | %+.2f | %s | %+.2f |" % (
            "60 mm" if x.get("side", "high") == "high" else "0 mm", x.get("phase"), x["target"], _f(x["measured"], 2),
            x["steady_pct"], _f(x["estimate"], 2), x["estimation_pct"]))
    add("")


def _poly(coeffs, var):
    n = len(coeffs) - 1
    return " + ".join("%.4g %s^%d" % (c, var, n - i) if n - i else "%.4g" % c for i, c in enumerate(np.asarray(coeffs, float)))
