"""`host experiment paper`: calibrate, then run the paper's experiments, then write the report.

One session on one board: the guided calibration (all three steps, logged), Fig. 3a from the
logged pot sweep, Fig. 5 from the logged no-load sweep, Fig. 7 before (nominal 2-point pots) and
after, Fig. 8 with and without the Df correction, the dead zone and Table 1. Every number in
DIR/report.md is measured in this run. Targets and rounds are reduced from the paper to keep the
virtual-board run short; the report says so.
"""

import csv
import time
from pathlib import Path


from host.experiments import displacement, figures, force_runs, held_out, model_compare, report, variants
from host.guided import stroke
from host.guided.flow import BRINGUP, STEPS, run_steps
from host.guided.force_calibration import gauge_sides
from host.guided.force_identification import SIDES
from host.guided.friction_trim import PRELOAD_N


def _save_sweep(path, data):
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["raw", "reference", "direction"])
        for x, y, d in zip(data["raw"], data["ref"], data["direction"]):
            w.writerow([int(x), "%.5f" % y, int(d)])


def _save_columns(path, columns):
    """Named columns of numbers as CSV, in the order measured: what a later refit starts from."""
    names = list(columns)
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(names)
        for row in zip(*(columns[n] for n in names)):
            w.writerow(["%.6g" % float(v) for v in row])


def save_results(path, results):
    """The run's measured results as JSON (numpy values as plain numbers)."""
    import json

    def plain(v):
        if hasattr(v, "tolist"):
            return v.tolist()
        raise TypeError("not JSON: %r" % (v,))

    Path(path).write_text(json.dumps(results, default=plain, indent=1) + "\n")


def paper_method_offline(pots, assembly, force):
    """The paper's fits on this run's own data, for comparison: BCM-3 per pot, a quartic Df, a
    quadratic F0(d) without friction on the 60 mm side's points (the paper's rig). (The Df and
    force data were converted with this run's curves; the closed-loop figures of the paper's
    method need a run of their own: --paper-method.)"""
    import numpy as np

    from host.fitting.assembly import binned_peak, fit_df
    from host.fitting.force import fit_force
    from host.fitting.models import fit_model
    from host.guided.force_identification import TAUT_N

    out = {}
    for pot in ("pot1", "pot2"):
        fit = fit_model("bcm", pots[pot]["raw"], pots[pot]["ref"], 3)
        out[pot] = {"rms_mm": fit.rms, "max_mm": fit.max_abs}
    _, resid, _, _ = fit_df(assembly["d1_mm"], assembly["df_mm"], 4)
    out["df4_binned_mm"] = binned_peak(assembly["d1_mm"], resid)
    f = np.asarray(force["force_n"])
    pulled = f < -TAUT_N
    if np.count_nonzero(pulled) > 6:
        out["force2_rms_n"] = fit_force(np.asarray(force["d_mm"])[pulled], f[pulled], np.asarray(force["s"])[pulled],
                                        2, friction=False).rms_n
    return out


class Progress:
    """Where a run is, and its results saved after every section: a run that stops (board gone,
    timeout, Ctrl-C) keeps everything it measured in results.json."""

    def __init__(self, out_dir, results):
        self.path = Path(out_dir) / "results.json"
        self.results = results
        results.setdefault("completed", [])
        self.phase = "start"

    def start(self, phase):
        self.phase = phase
        self.results["phase"] = phase

    def done(self):
        self.results["completed"].append(self.phase)
        save_results(self.path, self.results)


def write_stopped(out_dir, results, phase, why):
    """results.json and a report.md that say where and why the run stopped, with what it had
    measured by then (the full report when every section it needs is there, else a summary)."""
    results["stopped"] = {"phase": phase, "why": why}
    save_results(Path(out_dir) / "results.json", results)
    lines = ["# The paper's experiments: stopped", "",
             "The run stopped during **%s**: %s" % (phase, why), "",
             "Completed sections, saved in results.json: %s." % (", ".join(results.get("completed") or ["none"])), ""]
    for step in results.get("calibration_steps") or []:
        lines += ["## calibration step %s: %s" % (step["step"], "accepted" if step["accepted"] else "NOT accepted"), ""]
        lines += ["- " + line for line in step["lines"]] + [""]
    for key in ("pot_models", "fig5", "fig7", "fig8", "dead_zone", "table1"):
        if key in results:
            lines += ["## %s" % key, "", "```", json_text(results[key]), "```", ""]
    path = Path(out_dir) / "report.md"
    path.write_text("\n".join(lines))
    return path


def json_text(v):
    import json

    return json.dumps(v, indent=1, default=lambda x: x.tolist() if hasattr(x, "tolist") else str(x))[:4000]


class PaperRun:
    """One run of the paper's experiments: the board, the rig and the options every phase reads, and
    what earlier phases found that later ones need (the accepted calibration, the reference zero,
    the targets, the held-out draws)."""

    def __init__(self, session, rig, prompter, opts, out_dir, say, held_out_seed):
        import numpy as np

        self.session, self.rig, self.prompter, self.opts, self.say = session, rig, prompter, opts, say
        self.out_dir = Path(out_dir)
        self.calibrated = Path(opts.out)
        self.seed = held_out.draw_seed() if held_out_seed is None else int(held_out_seed)
        self.rng = np.random.default_rng(self.seed)
        self.held_out = figures.HeldOut(seed=self.seed)
        self.accepted = None  # step name -> the guided step's result, after the calibration phase

    def describe(self, results):
        """What the report says about the board, the model asked for and the stroke, before any phase."""
        session, opts = self.session, self.opts
        results.update({"board": session.board["name"], "simulated": session.simulated,
                        "chip": getattr(session.virtual, "chip", None), "port": session.port,
                        "interpreter": (session.client.status_info or {}).get("interpreter")})
        block = (session.actuator or {}).get("block") or {}
        results["sim_block_friction_n"] = block.get("coulomb_n")  # the model's, for the report's explanation
        results["preload_n"] = PRELOAD_N
        results["stroke_mm"] = [session.client.call("get", name) / 1000.0 for name in ("stroke_min_um", "stroke_max_um")]
        from host.fitting.pot_fit import DEFAULT_ORDER

        order = opts.order if opts.order is not None else DEFAULT_ORDER.get(opts.model)
        results["model"] = "%s%s" % (opts.model, "" if order is None else " order %d" % order)
        if opts.model == "auto":
            results["model"] += " (budget %d numbers)" % opts.budget

    def calibration(self, results):
        """All of the guided calibration (bringup first, as a full `host calibrate` does: wiring
        checks and, with --fix, the board-file settings it recommends), logged; its data saved as
        CSV for a later refit; Fig. 5 is the assembly step's own sweep."""
        from host.guided.run_log import RunLog

        session, opts = self.session, self.opts
        self.say("== calibration (all steps) ==")
        log = RunLog(opts.out, "host experiment paper", board=session.board["name"])
        results["calibration_steps"] = log.results["steps"]  # each step's lines as it finishes, for a stopped run
        accepted = run_steps(session, self.rig, self.prompter, (BRINGUP,) + STEPS, opts, log=log)
        log.finish()
        missing = [s for s in STEPS if s not in accepted]
        if missing:
            from host.errors import UserError

            raise UserError("the experiments need every calibration step; not accepted: %s" % ", ".join(missing))
        self.accepted = accepted
        pots, asm, frc = accepted["pots"].data, accepted["assembly"].data, accepted["force"].data
        for pot in ("pot1", "pot2"):
            _save_sweep(self.out_dir / ("sweep-%s.csv" % pot), pots[pot])
        _save_columns(self.out_dir / "df-samples.csv", {"d1_mm": asm["d1_mm"], "df_mm": asm["df_mm"], "direction": asm["direction"]})
        _save_columns(self.out_dir / "force-points.csv", {"d_mm": frc["d_mm"], "force_n": frc["force_n"], "s": frc["s"],
                                                          "loading": frc["loading"], "duty": frc["duty"]})
        results["stroke_nominal_mm"] = list(opts.stroke)  # follow_the_actuator set it from the board
        status = session.client.call("status")
        results["stroke_in_force_mm"] = [v / 1000.0 for v in status["stroke_um"]]
        # the end stops the pots step measured, in D2's frame: pot 2's mounting error can stretch or
        # shrink the stroke it sees (56.9 mm of a 60 mm one on a fresh actuator), and a target 1 mm
        # inside the nominal ends could then lie past the soft limit (the run never settled there)
        results["stroke_measured_mm"] = ([v / 1000.0 for v in status["end_stops_um"]] if status.get("end_stops_um")
                                         else list(opts.stroke))
        optional = lambda v: None if v is None else list(v)  # noqa: E731
        force_fit = {"coeffs_f": list(frc["coeffs_f"]), "coeffs_d": list(frc["coeffs_d"]),
                     "hysteresis_n": frc["hysteresis_n"], "friction_n": frc["friction_n"],
                     "rms_n": frc["rms_n"], "rms_plain_n": frc["rms_plain_n"], "sides": list(frc["sides"]),
                     "kind": frc.get("kind", "poly"), "knots_d": optional(frc.get("knots_d")),
                     "knots_f": optional(frc.get("knots_f")), "kinks_mm": optional(frc.get("kinks_mm"))}
        method = {"df_order": opts.df_order, "force_order": opts.force_order, "gauge_sides": opts.gauge_sides,
                  "friction": opts.friction, "budget": opts.budget, "rounds": opts.rounds,
                  "force_order_chosen": int(frc["order"])}
        return [figures.Calibration(
                    lines={s: accepted[s].lines for s in (BRINGUP,) + STEPS},
                    plots=[p.name for s in STEPS for p in accepted[s].plots],
                    pot_models={pot: "%s order %d" % (pots[pot]["fit"].model, pots[pot]["fit"].order) for pot in ("pot1", "pot2")},
                    paper_method_offline=paper_method_offline(pots, asm, frc), force_fit=force_fit, method=method),
                figures.Fig5(asm["stats"])]

    def held_out_df(self, results):
        """Df on a validation sweep the fit never saw, with the calibration on the board."""
        self.say("== held out: what the calibration never saw (targets drawn with seed %d) ==" % self.seed)
        self.held_out.store(results)  # the seed first: a run that stops in the sweep can still be repeated
        duty = max(100, int(self.opts.duty * held_out.SWEEP_DUTY_FACTOR))
        df = self.held_out.df = held_out.df_validation(self.session, self.rig, duty, self.say)
        self.say("  Df held out: %.3f mm peak of 1 mm bin means, the two directions averaged (%.3f mm pooled; the "
                 "friction's deflection %+.3f mm)" % (df["peak_binned_mm"], df.get("peak_pooled_mm", float("nan")),
                                                     df.get("friction_deflection_mm", float("nan"))))
        return [self.held_out]

    def fig3a(self, results):
        """The objective against the order, on this run's pot 2 sweep."""
        self.say("== Fig. 3a: objective vs order (pot 2 sweep of this run) ==")
        p2 = self.accepted["pots"].data["pot2"]
        rows, _ = model_compare.run(p2["raw"], p2["ref"], p2["noise"], self.out_dir, "pot 2", self.say)
        return [figures.Fig3a(rows)]

    def fig7_fig8(self, results):
        """Positions before (nominal 2-point pots) and after; no-load force runs without the Df
        correction and with it; the held-out positions with the accepted calibration."""
        session, rig, opts, say, out_dir = self.session, self.rig, self.opts, self.say, self.out_dir
        say("== Fig. 7 before: nominal 2-point pot calibration ==")
        pots = self.accepted["pots"].data
        session.flash(variants.write_nominal(out_dir / "calibration-nominal.json", self.calibrated, pots, session.board["adc_bits"]))
        middle = stroke.middle(opts.stroke)
        zero = displacement.zero_at_stops(session, rig, opts.ref_scale, middle_mm=middle)
        targets = stroke.position_targets(results["stroke_measured_mm"], results["stroke_in_force_mm"])
        say("  reference zeroed at the block's end stops: %.3f and %.3f mm, shift %+.3f mm" % (zero["low"], zero["high"], zero["shift"]))
        before = displacement.run_targets(session, rig, opts.ref_scale, zero, targets=targets, label="before")

        say("== Fig. 8 without the Df correction ==")
        session.flash(variants.write_without_df(out_dir / "calibration-without-df.json", self.calibrated))
        blocking = [("without Df", force_runs.blocking_run(session, rig, 5.0, middle))]

        say("== with the accepted calibration: Fig. 7 after, Fig. 8, dead zone, Table 1 ==")
        session.flash(self.calibrated)
        after = displacement.run_targets(session, rig, opts.ref_scale, zero, targets=targets, label="after")
        drawn = held_out.draw_positions(self.rng, results["stroke_in_force_mm"], paper_targets=targets)
        say("  held-out positions (drawn): %s mm" % ", ".join("%g" % t for t in drawn))
        self.held_out.positions = held_out.positions(session, rig, opts.ref_scale, zero, drawn)
        self.held_out.store(results)  # kept should the blocking runs below stop the run
        held = force_runs.board_force_range(session.client)
        not_run = []
        for target in (5.0, 1.0, 10.0, -1.0, -5.0, -10.0):
            if force_runs.refused(target, held):  # beyond what the force step held: the board refuses it
                say("  %+.0f N at no load is not run: beyond the force range the calibration held (%+.2f .. %+.2f N)"
                    % (target, held[0], held[1]))
                not_run.append(("not run", {"final": None, "target_n": target}))
                continue
            blocking.append(("with Df", force_runs.blocking_run(session, rig, target, middle)))
        displacement.plot(out_dir / "fig7.png", before, after)
        force_runs.plot_blocking(out_dir / "fig8.png", blocking[:2])
        runs = [(name, {k: v for k, v in run.items() if k in ("final", "target_n")}) for name, run in blocking] + not_run
        return [figures.Fig7(before=before, after=after, reference_zero=zero), figures.Fig8(runs), self.held_out]

    def dead_zone(self, results):
        self.say("== force dead zone ==")
        rows, dead_zone_n = force_runs.dead_zone(self.session, self.rig, self.prompter, self.opts.anchor_mm)
        return [figures.DeadZone(rows=rows, dead_zone_n=dead_zone_n)]

    def _reached(self):
        """The force each gauge side's force step reached: the steps and draws stay inside it."""
        return held_out.side_ranges(self.accepted["force"].data, gauge_sides(self.opts.gauge_sides))

    def table1(self, results):
        self.say("== Table 1: force steps ==")
        reached = self._reached()
        sides = gauge_sides(self.opts.gauge_sides)
        refused = [{"side": side, "target": SIDES[side] * m, "reached_n": reached[side]}
                   for side in sides for m in force_runs.beyond_reach(force_runs.STEPS_N, reached[side])]
        for x in refused:
            self.say("  %+.0f N on the %s side is not run: beyond the %.2f N the force step held there" % (
                x["target"], x["side"], x["reached_n"]))
        return [figures.Table1([row for side in sides
                                for row in force_runs.force_steps(self.session, self.rig, self.prompter, self.opts.anchor_mm,
                                                                  side, reached_n=reached[side])]),
                figures.Table1Refused(refused)]

    def held_out_forces(self, results):
        """Force steps at forces drawn fresh, away from those the trim and its F0 check held: at the
        gauge's anchor, where the force step was made, then at another position (held_out.py)."""
        opts = self.opts
        self.say("== held-out force steps (drawn) ==")
        self.held_out.force_draws, self.held_out.forces = self._drawn_steps(opts.anchor_mm, held_out.LOADING, held_out.UNLOADING)
        self.held_out.store(results)  # kept should the steps elsewhere stop the run
        away = held_out.away_anchor_mm(opts.stroke, opts.anchor_mm)
        self.say("  at D2 = %g mm, away from the calibration's anchor (%g mm):" % (away, opts.anchor_mm))
        draws, rows = self._drawn_steps(away, held_out.AWAY_LOADING, held_out.AWAY_UNLOADING)
        self.held_out.away = {"anchor_mm": away, "calibrated_at_mm": opts.anchor_mm, "force_draws": draws, "forces": rows}
        return [self.held_out]

    def _drawn_steps(self, anchor_mm, loading, unloading):
        """({side: what was drawn and why}, rows) of force steps drawn on each side and run with the
        gauge hooked at `anchor_mm`."""
        opts, force = self.opts, self.accepted["force"].data
        reached = self._reached()
        rows, draws = [], {}
        for side in gauge_sides(opts.gauge_sides):
            held = held_out.held_by_calibration(reached[side]) if opts.trim and opts.friction else []
            magnitudes = held_out.draw_forces(self.rng, reached[side], held, held_out.side_levels(force, side),
                                              loading=loading, unloading=unloading)
            draws[side] = {"reached_n": reached[side], "held_by_calibration_n": held, "drawn_n": magnitudes}
            self.say("  %s side (reached %.1f N; the calibration held %s N): %s N" % (
                side, reached[side], ", ".join("%g" % h for h in held) or "-", ", ".join("%g" % m for m in magnitudes) or "none"))
            if magnitudes:
                rows += held_out.forces(self.session, self.rig, self.prompter, anchor_mm, side, magnitudes)
        return draws, rows


# (progress name, phase) in the order they run: each phase returns the figures it measured
PHASES = (("calibration", PaperRun.calibration), ("held-out Df", PaperRun.held_out_df), ("Fig. 3a", PaperRun.fig3a),
          ("Fig. 7 and Fig. 8", PaperRun.fig7_fig8), ("force dead zone", PaperRun.dead_zone), ("Table 1", PaperRun.table1),
          ("held-out force steps", PaperRun.held_out_forces))


def run_paper(session, rig, prompter, opts, out_dir, say=None, results=None, held_out_seed=None):
    """Every phase in order, each one's figures stored and results.json saved after it (a run that
    stops keeps what it measured); then the report. Returns (report path, results). `say(text)`:
    its progress lines (default: the terminal's note, on stderr)."""
    if say is None:
        from host.terminal import note as say
    t0 = time.monotonic()
    results = {} if results is None else results
    run = PaperRun(session, rig, prompter, opts, out_dir, say, held_out_seed)
    run.describe(results)
    timings = {}
    progress = Progress(out_dir, results)
    for name, phase in PHASES:
        progress.start(name)
        t = time.monotonic()
        for figure in phase(run, results):
            figure.store(results)
        timings[name] = time.monotonic() - t
        progress.done()
    timings["total"] = time.monotonic() - t0
    results["timings"] = timings  # last: bench_robustness.py takes it as the sign that a run ended
    results.pop("phase", None)
    save_results(progress.path, results)  # results.json first: a report bug must not lose the run
    progress.start("the report")
    path = report.write(out_dir, results, opts)
    return path, results
