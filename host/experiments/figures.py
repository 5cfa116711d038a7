"""What each of the paper's figures measured: one dataclass per figure.

A phase of `host experiment paper` (host/experiments/paper.py) returns one of these; `store` puts
it into the run's results under its key, the only way a figure enters results.json. The report
(host/experiments/report.py) and bench/bench_paper.py read results.json back, so the stored form
(`payload`) is the file's format: change a field here and both see it.
"""

from dataclasses import dataclass, fields


class Figure:
    """A figure's measurements and the results.json key they are stored under."""

    KEY = None

    def payload(self):
        """The JSON form: the fields by name, those not measured (None) left out."""
        return {f.name: getattr(self, f.name) for f in fields(self) if getattr(self, f.name) is not None}

    def store(self, results):
        results[self.KEY] = self.payload()


class OneField(Figure):
    """A figure stored as its one field's value (a list of rows, the step's own stats dict)."""

    def payload(self):
        return getattr(self, fields(self)[0].name)


@dataclass
class Calibration(Figure):
    """The guided calibration the experiments run on: each step's lines and plots, the pot models it
    chose, the force fit and method, and the paper's own fits on the same data for comparison.
    Stored as top-level keys (older runs' results.json have them there)."""

    lines: dict  # step name -> the lines it printed
    plots: list  # file names of the steps' plots
    pot_models: dict  # "pot1"/"pot2" -> "bcm order 3"
    paper_method_offline: dict
    force_fit: dict
    method: dict

    def store(self, results):
        results.update({"calibration": self.lines, "calibration_plots": self.plots, "pot_models": self.pot_models,
                        "paper_method_offline": self.paper_method_offline, "force_fit": self.force_fit,
                        "method": self.method})


@dataclass
class Fig3a(OneField):
    """The fit objective against the model order on pot 2's sweep (host/experiments/model_compare.py)."""

    KEY = "fig3a"
    rows: list


@dataclass
class Fig5(OneField):
    """Df before and after the assembly calibration, from the assembly step's own sweep (in-sample)."""

    KEY = "fig5"
    stats: dict


@dataclass
class Fig7(Figure):
    """Position errors at the targets with a nominal 2-point pot calibration (before) and the
    accepted one (after), against the reference zeroed at the block's end stops."""

    KEY = "fig7"
    before: list
    after: list
    reference_zero: dict


@dataclass
class Fig8(OneField):
    """No-load force runs: (name, {final, target_n}) without the Df correction and with it."""

    KEY = "fig8"
    runs: list


@dataclass
class DeadZone(Figure):
    """The smallest force step the loop turns into motion."""

    KEY = "dead_zone"
    rows: list
    dead_zone_n: float


@dataclass
class Table1(OneField):
    """The paper's force steps (5/10/15 N loading, then unloading) on each gauge side."""

    KEY = "table1"
    rows: list


@dataclass
class Table1Refused(OneField):
    """The paper's force steps not run: beyond the force the force step held on their side, which
    the board refuses ({side, target, reached_n} each)."""

    KEY = "table1_refused"
    rows: list


@dataclass
class HeldOut(Figure):
    """What the calibration never saw (host/experiments/held_out.py), filled phase by phase: Df on a
    validation sweep, positions and forces drawn with `seed`, and forces drawn with the gauge away
    from the calibration's anchor (`away`: anchor_mm, calibrated_at_mm, force_draws, forces). The
    targets are judged on these."""

    KEY = "held_out"
    seed: int
    df: dict = None
    positions: list = None
    force_draws: dict = None
    forces: list = None
    away: dict = None
