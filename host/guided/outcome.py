"""What a guided step hands back: the sections to write, what to show, and its data for reports."""

from dataclasses import dataclass, field


@dataclass
class StepOutcome:
    step: str  # "pots", "assembly" or "force"
    sections: dict  # calibration section name -> section dict (written only when accepted)
    lines: list  # fit statistics and check results, for the person
    plots: list  # PNG paths written
    ok: bool = True  # every check passed
    data: dict = field(default_factory=dict)  # arrays and figures for the experiments report
