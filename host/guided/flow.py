"""The guided calibration run: steps in order, show results, accept or abort, write, flash.

Accepted sections are written to the calibration file one by one (host.calibration_file:
update_section, atomic), then the file is flashed and the firmware must report its CRC before
the next step starts. A fresh full run starts a new file (stale Df/force sections computed with
older pot curves must not survive); single steps update the existing file.
"""

from dataclasses import dataclass, field
from pathlib import Path

from host.calibration_file import new_document, update_section, write_calibration
from host.errors import UserError
from host.guided.checks import Limits

STEPS = ("pots", "assembly", "force")


@dataclass
class Options:
    out: Path = Path("calibration.json")
    out_dir: Path = Path(".")  # where plots go
    reference: str = "adc"  # or "manual"
    ref_scale: tuple = None
    manual_points: int = 12
    model: str = "bcm"
    order: int = None
    budget: int = None  # --model auto: most numbers a pot curve may store
    duty: int = 1500
    df_order: object = "auto"
    force_order: object = "auto"
    gauge_sides: str = "both"  # "high" (the paper's rig), "low" or "both"
    friction: bool = True
    anchor_mm: float = 45.0
    rounds: int = 2
    levels: int = 8
    max_duty: int = 5000
    settle_s: float = 0.5
    limits: Limits = field(default_factory=Limits)
    flash: bool = True


def run_steps(session, rig, prompter, steps, opts):
    """Run `steps`; returns {step: StepOutcome} of the accepted ones."""
    from host.guided.assembly_calibration import calibrate_assembly
    from host.guided.force_calibration import calibrate_force
    from host.guided.pot_calibration import calibrate_pots

    path = Path(opts.out)
    board_name = session.board["name"]
    if tuple(steps) == STEPS:
        write_calibration(path, new_document(board=board_name))
        prompter.say("new calibration file %s" % path)
    elif "pots" not in steps and not path.exists():
        raise UserError("%s does not exist: calibrate the pots first (host calibrate pots)" % path)
    accepted = {}
    for step in steps:
        if step == "pots":
            outcome = calibrate_pots(session, rig, prompter, opts)
        elif step == "assembly":
            outcome = calibrate_assembly(session, rig, prompter, opts, path)
        else:
            outcome = calibrate_force(session, rig, prompter, opts, path)
        prompter.say("[%s] results:" % step)
        for line in outcome.lines:
            prompter.say("  " + line)
        for png in outcome.plots:
            prompter.say("  plot: %s" % png)
        if not outcome.sections:
            raise UserError("%s step produced no calibration: fix what the checks say and run it again" % step)
        question = "Accept the %s calibration?" % step
        if not outcome.ok:
            question = "Some checks FAILED (see above). Accept the %s calibration anyway?" % step
            if prompter.yes:
                raise UserError("%s step failed its checks (see above); not accepted under --yes" % step)
        if not prompter.accept(question):
            prompter.say("  %s not accepted: the calibration file keeps its previous %s sections" % (step, step))
            continue
        for name, section in outcome.sections.items():
            update_section(path, name, section, board=board_name)
        prompter.say("  wrote %s to %s" % (", ".join(outcome.sections), path))
        if opts.flash:
            session.flash(path)
        accepted[step] = outcome
    return accepted
