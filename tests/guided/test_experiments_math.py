"""The pieces of the experiments and guided fits that need no board: the nominal 2-point pot
calibration, the Df order choice by cross-validation, the force hysteresis measure."""

import pytest
import numpy as np

from firmware.calibration import convert, pot_constants
from host.experiments.variants import nominal_pot_section
from host.fitting.assembly import choose_order, fit_df
from host.fitting.force import hysteresis_n


def test_nominal_pot_is_the_line_through_the_end_readings():
    raw = np.linspace(300, 3900, 500)
    ref = 60 * ((raw - 300) / 3600) ** 1.3  # a bent pot
    section = nominal_pot_section(raw, ref, 12, "pot2")
    kind, k = pot_constants(section, "pot2")
    assert kind == "pwl"
    for code, want_um in ((300, 0.0), (2100, 30000.0), (3900, 60000.0)):
        assert abs(convert(kind, code, k) - want_um) <= 10  # straight line, not the bent curve


def test_df_order_by_cross_validation_finds_the_true_degree():
    rng = np.random.default_rng(2)
    x = np.sort(rng.uniform(0, 60, 2000))
    v = (x - 30) / 30
    df = 4.6 * v**4 - 0.5 * v**3 + 0.1 * v + rng.normal(0, 0.02, x.size)
    order, scores = choose_order(x, df, "auto")
    assert order == 4
    assert scores[3] > 2 * scores[4]
    coeffs, resid, used, _ = fit_df(x, df, 4)
    assert used == 4 and np.max(np.abs(resid)) < 0.1


def test_force_hysteresis_is_the_gap_between_loading_and_unloading():
    d = np.tile(np.linspace(-1.4, -0.2, 8), 2)
    loading = np.repeat([True, False], 8)
    f = 12.4 * d + np.where(loading, -0.3, 0.3)  # friction opposes the motion each way
    assert abs(hysteresis_n(d, f, loading, 2) - 0.6) < 1e-6
    assert np.isnan(hysteresis_n(d[:3], f[:3], loading[:3], 2))


def _results(after_error_mm, df_binned_mm, force_pct):
    """A results dict shaped like host.experiments.paper.run_paper's, with chosen figures."""
    targets = (1, 30, 59)
    fig7 = {
        "before": [{"target": float(t), "reference": t - 2.0, "error": 2.0, "d2": float(t), "settled": True} for t in targets],
        "after": [{"target": float(t), "reference": t - after_error_mm, "error": after_error_mm, "d2": float(t),
                   "settled": t != 59} for t in targets],
    }
    table1 = []
    for side, sign in (("high", -1.0), ("low", 1.0)):
        for m, phase in ((5.0, "loading"), (10.0, "loading"), (15.0, "loading"), (10.0, "unloading"), (5.0, "unloading")):
            target = sign * m
            measured = target * (1 + force_pct / 100.0)
            table1.append({"target": target, "measured": measured, "estimate": measured, "side": side, "phase": phase,
                           "steady_pct": 100.0 * (measured - target) / abs(target), "estimation_pct": 0.0})
    return {
        "board": "sim", "simulated": True, "port": "sim", "model": "auto (budget 32 numbers)",
        "pot_models": {"pot1": "pwl order 12", "pot2": "pwl order 11"},
        "method": {"df_order": "auto", "force_order": "auto", "gauge_sides": "both", "friction": True, "budget": 32,
                   "rounds": 2, "force_order_chosen": 4},
        "calibration": {"pots": ["pot1 fit: pwl"], "assembly": ["Df: order 7"], "force": ["force: h"]},
        "calibration_plots": ["calibration-pot1.png"],
        "paper_method_offline": {"pot1": {"rms_mm": 0.075, "max_mm": 0.19}, "pot2": {"rms_mm": 0.095, "max_mm": 0.42},
                                 "df4_binned_mm": 0.3, "force2_rms_n": 0.22},
        "fig3a": [{"model": "bcm", "order": 3, "norm2": 3.9}] + [{"model": "pcm", "order": n, "norm2": 40.0 / n} for n in range(2, 13)],
        "fig5": {"order": 7, "peak_before_mm": 4.5, "peak_after_mm": 0.15, "peak_after_binned_mm": df_binned_mm,
                 "rms_after_mm": 0.037, "n_samples": 1964},
        "force_fit": {"coeffs_f": [0.25, -0.08, 12.6, 0.03], "coeffs_d": [0.0, 0.079, 0.0], "hysteresis_n": 0.53,
                      "friction_n": 0.21, "rms_n": 0.03, "rms_plain_n": 0.24, "sides": ["high", "low"]},
        "fig7": fig7,
        "fig8": [("without Df", {"final": 40.2, "target_n": 5.0}), ("with Df", {"final": 59.4, "target_n": 5.0}),
                 ("with Df", {"final": 0.6, "target_n": -1.0})],
        "dead_zone": {"rows": [{"target": -0.2, "measured": -0.1, "estimate": -0.2}], "dead_zone_n": 0.2},
        "table1": table1,
        "timings": {"calibration": 100.0, "total": 250.0},
        "stroke_mm": [0.5, 59.5], "sim_block_friction_n": 0.3, "preload_n": 0.5,
    }


def test_report_renders_every_section_and_judges_each_target(tmp_path):
    from types import SimpleNamespace

    from host.experiments import report

    opts = SimpleNamespace()  # everything the report says comes from the results
    text = report.write(tmp_path, _results(0.05, 0.2, 1.0), opts).read_text()
    for heading in ("## Summary", "## Fig. 3a", "## Fig. 5", "## Fig. 7", "## Fig. 8", "## Force dead zone", "## Table 1"):
        assert heading in text
    lines = {line.split("|")[1].strip(): line for line in text.splitlines() if line.startswith("| ")}
    assert "<= 0.1 mm (paper's targets): met" in lines["displacement control (Fig. 7), max error 1-59 mm"]
    assert "NOT met" in lines["Df calibration (Fig. 5)"]  # 0.2 mm of bin means
    assert "no blocking at +-1 to 10 N: met" in lines["force control 5 N at no load from 30 mm (Fig. 8)"]
    assert "worst of all 10 steps (both signs, loading and unloading; next to where the calibration's trim held) 1.0 %" in text
    assert "<= 2 % (the paper's steps): met" in text
    assert "0.30 N in the simulated actuator's file, 6 % of 5 N" in text and "(0.5 and 59.5 mm)" in text
    assert "Df order: auto -> order 7. Force: order auto -> 4" in text and "2 force identification rounds" in text
    assert "a 0.5 N preload took up the fibre's slack" in text
    assert "| 30 | 28.000 | 2.000 | 29.950 | 0.050 |" in text and "0.050 (not settled)" in text  # 59 mm unsettled
    worse = report.write(tmp_path, _results(0.5, 0.05, 3.0), opts).read_text()
    assert "<= 0.1 mm (paper's targets): **NOT met**" in worse and "<= 2 % (the paper's steps): **NOT met**" in worse


def test_the_targets_are_judged_on_the_held_out_figures(tmp_path):
    """A run with held-out figures is judged on them, whatever the paper's own figures say: good
    in-sample figures with poor held-out ones miss, and the other way round meet."""
    from types import SimpleNamespace

    from host.experiments import report

    def with_held_out(results, df_mm, error_mm, force_pct):
        results["held_out"] = {
            "seed": 123, "df": {"peak_binned_mm": df_mm, "duty": 1200, "n_samples": 1900},
            "positions": [{"target": t, "reference": t - error_mm, "error": error_mm, "d2": t, "settled": True}
                          for t in (7.3, 21.9, 48.2)],
            "forces": [{"target": -6.2, "measured": -6.2 * (1 + force_pct / 100), "estimate": -6.2, "side": "high",
                        "phase": "loading", "steady_pct": -force_pct, "estimation_pct": 0.1}],
            "force_draws": {"high": {"reached_n": 16.0, "held_by_calibration_n": [4.8, 9.6, 14.4], "drawn_n": [6.2]}}}
        return results

    opts = SimpleNamespace()
    miss = report.write(tmp_path, with_held_out(_results(0.05, 0.02, 1.0), 0.3, 0.4, 3.0), opts).read_text()
    lines = {line.split("|")[1].strip(): line for line in miss.splitlines() if line.startswith("| ")}
    assert "held out: 0.300 mm" in lines["Df calibration (Fig. 5)"] and "(bin means, held out): **NOT met**" in lines["Df calibration (Fig. 5)"]
    assert "(both): **NOT met**" in lines["displacement control (Fig. 7), max error 1-59 mm"]
    assert "<= 2 % (held out): **NOT met**" in miss
    assert "## Held out: what the calibration never saw" in miss and "`--held-out-seed 123`" in miss
    meet = report.write(tmp_path, with_held_out(_results(0.05, 0.2, 3.0), 0.05, 0.02, 1.0), opts).read_text()
    lines = {line.split("|")[1].strip(): line for line in meet.splitlines() if line.startswith("| ")}
    assert "(bin means, held out): met" in lines["Df calibration (Fig. 5)"]
    assert "(both): met" in lines["displacement control (Fig. 7), max error 1-59 mm"]
    # positions are never calibration points: a miss at the paper's own targets is a miss
    far = report.write(tmp_path, with_held_out(_results(0.5, 0.2, 3.0), 0.05, 0.02, 1.0), opts).read_text()
    lines = {line.split("|")[1].strip(): line for line in far.splitlines() if line.startswith("| ")}
    assert "(both): **NOT met**" in lines["displacement control (Fig. 7), max error 1-59 mm"]
    assert "<= 2 % (held out): met" in meet


def test_force_steps_away_from_the_calibrations_position_are_judged_apart(tmp_path):
    """The force steps with the gauge away from the force calibration's anchor are their own
    target: a miss there is a miss whatever the steps at the anchor say, and a run from before
    they existed is not judged on them."""
    from types import SimpleNamespace

    from host.experiments import report
    from host.experiments.targets import headline, judged

    def with_away(steady_pct):
        results = _results(0.05, 0.05, 1.0)
        row = {"target": -7.1, "measured": -7.1 * (1 + steady_pct / 100), "estimate": -7.1, "side": "high",
               "phase": "loading", "steady_pct": steady_pct, "estimation_pct": 0.3}
        results["held_out"] = {"seed": 7, "forces": [dict(row, steady_pct=0.5)],
                               "away": {"anchor_mm": 30.0, "calibrated_at_mm": 45.0, "forces": [row],
                                        "force_draws": {"high": {"reached_n": 16.0, "held_by_calibration_n": [],
                                                                 "drawn_n": [7.1]}}}}
        return results

    assert judged(headline(_results(0.05, 0.05, 1.0)))["force elsewhere"] is None
    far = with_away(-4.0)
    ok = judged(headline(far), far)
    assert ok["force steps"] and ok["force elsewhere"] is False
    text = report.write(tmp_path, far, SimpleNamespace()).read_text()
    lines = {line.split("|")[1].strip(): line for line in text.splitlines() if line.startswith("| ")}
    row = lines["force steps away from the calibration's position (the paper's Table 1 ran at mid stroke)"]
    assert "D2 = 30 mm, the force calibration's at 45 mm" in row and "worst 4.0 % steady-state" in row
    assert row.endswith("<= 2 % (held out): **NOT met** |")
    assert "**Force steps away from the calibration's position**" in text and "| 60 mm | loading | -7.10 |" in text
    near = with_away(1.5)
    assert judged(headline(near), near)["force elsewhere"] is True


def test_a_step_beyond_the_calibrated_range_is_said_to_be_so(tmp_path):
    """A 15 N step on a spring whose force step reached 15.5 N: not a silent miss, but a step the
    calibration never showed the actuator could hold, said in the table and under it."""
    from types import SimpleNamespace

    from host.experiments import report

    results = _results(0.05, 0.05, 1.0)
    for row in results["table1"]:
        row["reached_n"] = 15.5
        row["in_range"] = abs(row["target"]) <= 0.9 * 15.5
    text = report.write(tmp_path, results, SimpleNamespace()).read_text()
    assert "(beyond 90 % of the 15.5 N the force step reached on this side)" in text
    assert "**Near the end of the calibrated range:** -15, +15 N" in text
    assert "**Not run:**" not in text


def test_a_step_beyond_what_the_force_step_held_is_not_run_and_said_so(tmp_path):
    """On a spring whose force step held 12.0 N on the 0 mm side, +15 N is left out of the
    sequence (the board would refuse it) and the report names it with the reason."""
    from types import SimpleNamespace

    from host.experiments import force_runs, report

    assert force_runs.beyond_reach(force_runs.STEPS_N, 12.0) == [15.0]
    assert force_runs.beyond_reach(force_runs.STEPS_N, 9.0) == [10.0, 15.0]
    assert force_runs.beyond_reach(force_runs.STEPS_N, None) == []
    results = _results(0.05, 0.05, 1.0)
    results["table1"] = [row for row in results["table1"] if row["target"] != 15.0]
    results["table1_refused"] = [{"side": "low", "target": 15.0, "reached_n": 12.0}]
    text = report.write(tmp_path, results, SimpleNamespace()).read_text()
    assert "**Not run:** +15 N (0 mm side, held 12.00 N): beyond the force the force step held" in text


@pytest.mark.parametrize("failure", [TimeoutError("no reply to stream"), KeyboardInterrupt()], ids=["board-gone", "ctrl-c"])
def test_a_stopped_experiment_keeps_what_it_measured(tmp_path, monkeypatch, capsys, failure):
    """The board stops answering (or Ctrl-C) in the middle of the control experiments: the
    sections measured before are in results.json, report.md says where and why it stopped, and
    the command ends with one error line and status 1, no traceback."""
    import json

    import host.experiments.paper as paper
    import host.guided.session as session_mod
    from host import cli

    def fake_run_paper(session, rig, prompter, opts, out_dir, say=print, results=None, **kw):
        results.update({"board": "sim", "simulated": True, "port": "sim"})
        progress = paper.Progress(out_dir, results)
        progress.start("calibration")
        results["pot_models"] = {"pot1": "pwl order 12", "pot2": "pwl order 11"}
        results["fig5"] = {"order": 7}
        progress.done()
        progress.start("Fig. 7 and Fig. 8")
        results["fig7"] = {"before": [{"target": 1.0}]}
        raise failure

    class FakeSession:
        def __init__(self, *a, **k):
            self.board = {"name": "sim", "adc_bits": 12, "simulated": True}
            self.actuator = {}

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            return False

    monkeypatch.setattr(paper, "run_paper", fake_run_paper)
    monkeypatch.setattr(session_mod, "Session", FakeSession)
    monkeypatch.setattr("host.commands.experiment.make_rig", lambda *a: None, raising=False)
    monkeypatch.setattr("host.guided.rig.reference_scale", lambda *a: 1.0)
    out = tmp_path / "run"
    code = cli.main(["experiment", "paper", "--port", "sim", "--out", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 1
    assert len(err) == 1 and err[0].startswith("error: the experiment stopped during Fig. 7 and Fig. 8: "), err
    assert "Traceback" not in "\n".join(err)
    saved = json.loads((out / "results.json").read_text())
    assert saved["completed"] == ["calibration"] and saved["fig5"] == {"order": 7}
    assert saved["stopped"]["phase"] == "Fig. 7 and Fig. 8"
    report = (out / "report.md").read_text()
    assert "stopped during **Fig. 7 and Fig. 8**" in report and "pwl order 12" in report


def test_a_runs_samples_are_saved_as_named_columns_in_the_order_taken(tmp_path):
    """df-samples.csv and force-points.csv (host.experiments.paper._save_columns): what a later
    refit reads back, with the booleans and duties as numbers."""
    from host.experiments.paper import _save_columns

    cols = {"d_mm": np.array([-0.18447, 0.512, 0.3]), "loading": np.array([True, True, False]),
            "duty": np.array([-625.0, 1250.0, 625.0])}
    _save_columns(tmp_path / "points.csv", cols)
    back = np.genfromtxt(tmp_path / "points.csv", delimiter=",", names=True)
    assert back.dtype.names == ("d_mm", "loading", "duty")
    assert np.allclose(back["d_mm"], cols["d_mm"]) and list(back["loading"]) == [1, 1, 0]
    assert list(back["duty"]) == [-625, 1250, 625]


def test_a_run_that_stops_in_the_held_out_sweep_keeps_its_seed(monkeypatch, tmp_path):
    """The held-out seed is in results (and so in the stopped run's results.json) before the
    validation sweep starts: `--held-out-seed` can repeat a run that stopped there."""
    from types import SimpleNamespace

    import host.experiments.paper as paper

    def board_gone(*args, **kwargs):
        raise TimeoutError("no telemetry")

    monkeypatch.setattr(paper.held_out, "df_validation", board_gone)
    run = paper.PaperRun(None, None, None, SimpleNamespace(out=tmp_path / "c.json", duty=1500), tmp_path,
                         lambda text: None, held_out_seed=77)
    results = {}
    with pytest.raises(TimeoutError):
        run.held_out_df(results)
    assert results["held_out"] == {"seed": 77}


class _StatusClient:
    """A board's client that answers `status` with a force range (mN), as the firmware does."""

    def __init__(self, force_range_mn):
        self.force_range_mn = force_range_mn

    def call(self, name, *args):
        assert name == "status", name
        return {"force_range_mN": self.force_range_mn}


def test_steps_left_out_leave_no_hold_repeated_as_a_step(monkeypatch):
    """On a side that held 12 N, 5/10/15/10/5 N becomes 5/10/5 N (not 5/10/10/5, whose second 10 N
    hold would read as unloading); on one that held 3 N nothing is run at all."""
    from types import SimpleNamespace

    from host.experiments import force_runs

    held = []

    def hold_sequence(session, rig, prompter, anchor, side, targets, settle, measure, label, preload=False):
        held.append(list(targets))
        return targets, [t * 1.01 for t in targets], list(targets)

    monkeypatch.setattr(force_runs, "hold_sequence", hold_sequence)
    rig = SimpleNamespace(no_load=lambda: None)
    rows = force_runs.force_steps(None, rig, None, 45.0, "low", reached_n=12.0)
    assert held == [[5.0, 10.0, 5.0]]
    assert [(r["target"], r["phase"]) for r in rows] == [(5.0, "loading"), (10.0, "loading"), (5.0, "unloading")]
    assert force_runs.force_steps(None, rig, None, 45.0, "high", reached_n=3.0) == [] and len(held) == 1


def test_the_dead_zone_stops_at_the_force_range_the_board_takes(monkeypatch):
    from types import SimpleNamespace

    from host.experiments import force_runs

    asked = []

    def hold_sequence(session, rig, prompter, anchor, side, targets, settle, measure, label, preload=False):
        asked.extend(targets)
        return targets, [0.0] * len(targets), [0.0] * len(targets)

    monkeypatch.setattr(force_runs, "hold_sequence", hold_sequence)
    force_runs.dead_zone(SimpleNamespace(client=_StatusClient([-3000, 3000])), None, None, 45.0)
    assert min(asked) == -3.0 and len(asked) == 16  # 0 .. -3 N in 0.2 N steps; -3.2 .. -5 N refused
    asked.clear()
    force_runs.dead_zone(SimpleNamespace(client=_StatusClient(None)), None, None, 45.0)
    assert min(asked) == -5.0


def test_a_run_with_no_table1_step_reports_it_and_is_not_met(tmp_path):
    """Every Table 1 step beyond what the force step held (an actuator that held under 5 N): the
    report is written, the summary says '-', and the force target is not met (nothing measured)."""
    from types import SimpleNamespace

    from host.experiments import report
    from host.experiments.targets import headline, judged

    results = _results(0.05, 0.05, 1.0)
    results["table1"] = []
    results["table1_refused"] = [{"side": s, "target": sign * m, "reached_n": 4.0}
                                 for s, sign in (("high", -1.0), ("low", 1.0)) for m in (5.0, 10.0, 15.0)]
    results.pop("held_out", None)
    h = headline(results)
    assert h["worst_steady_pct"] is None and judged(h, results)["force steps"] is None
    text = report.write(tmp_path, results, SimpleNamespace()).read_text()
    assert "**Not run:** -5 N (60 mm side, held 4.00 N)" in text


def test_a_side_that_held_no_more_than_a_taut_fibre_is_not_a_measured_range():
    from host.guided.force_calibration import held_range

    section, line = held_range({"high": 17.86, "low": 0.0004})
    assert section["fixed"] == [-17860, 17860] and section["fit"]["assumed"] == [1], section
    assert "the positive side was not measured" in line
    assert held_range({"high": 0.2})[0] is None
