"""The guided calibration run: steps in order, show results, accept or abort, write, flash.

Nothing is written before a step is accepted. Before the first accepted step changes an
existing calibration file, the file is copied aside with the date in its name
(calibration.json.20261124-001500.bak), so no run, however it ends, loses a calibration. Then
each accepted step's sections are written in one atomic write (host.calibration.file.
CalibrationFile, which also owns what a change leaves out), the file is flashed and the firmware
must report its CRC before the next step starts. When a full run accepts new pot curves, the
file's Df, force, friction and end stops go with the old curves they were measured through (the
backup keeps them); a single `pots` step leaves out only the end stops (their frame moved), and
the other single steps change only their own sections.
An interrupted or failed step leaves the file as the last accepted step left it.

The bringup (host/guided/bringup.py: wiring, directions, pot assignment) is not a calibration
section: its record goes beside the calibration file (calibration.bringup.json), and a full
`host calibrate` runs it first unless that record says it passed on this board. Problems it
finds stop the run before any sweep (under --yes) or after the person declines to go on.
"""

import json

from dataclasses import dataclass, field
from pathlib import Path

from host.calibration.file import CalibrationFile
from host.errors import UserError
from host.fitting.model_select import DEFAULT_BUDGET
from host.guided.checks import Limits
from host.terminal import warn

STEPS = ("pots", "assembly", "gain", "force")


class StepRefused(UserError):
    """A step's verdict stopped the run (its checks failed, bringup found problems): the person
    has something to fix, as with any other user error (one line, exit status 2)."""
BRINGUP = "bringup"


@dataclass
class Options:
    out: Path = Path("calibration.json")
    out_dir: Path = Path(".")  # where plots go
    reference: str = "adc"  # or "manual"
    ref_scale: tuple = None
    manual_points: int = 12
    model: str = "auto"  # as host calibrate's --model
    order: int = None
    budget: int = DEFAULT_BUDGET  # --model auto: most numbers a pot curve may store
    duty: int = 1500
    df_order: object = "auto"
    force_order: object = "auto"
    gauge_sides: str = "both"  # "high" (the paper's rig), "low" or "both"
    friction: bool = True
    trim: bool = True  # force: trim h in closed loop once the force calibration is on the board (friction_trim.py)
    anchor_mm: float = None  # where the gauge's fibre goes taut; None: from the stroke (stroke.gauge_anchor_mm)
    stroke: tuple = None  # the block's nominal stroke (mm); None: from the board (follow_the_actuator)
    rounds: int = 2
    levels: int = 8
    max_duty: int = 9000
    force_range: float = 16.0
    settle_s: float = 0.5
    limits: Limits = field(default_factory=Limits)
    flash: bool = True
    fix: bool = False  # bringup: write and flash a corrected board file without asking

    def plot_path(self, what):
        """Where a step's plot goes: OUT-what.png in out_dir (calibration-pot1.png for
        calibration.json), so two calibrations in one folder keep their own plots."""
        return Path(self.out_dir) / ("%s-%s.png" % (Path(self.out).stem, what))


def follow_the_actuator(opts, session):
    """Fill in what follows the actuator's stroke (host/guided/stroke.py) unless given: the stroke
    itself, the range a pot's sweep must cover (90 % of it; the pots step narrows it to 90 % of the
    end stops' distance as each pot's reference read them, which must reach 80 % of the stroke:
    pot_calibration.sweep_limits), the gauge's anchor (75 % along it)."""
    import dataclasses

    from host.guided import stroke

    if opts.stroke is None:
        opts.stroke = stroke.nominal(session.board, getattr(session, "actuator", None))
        opts.limits = dataclasses.replace(opts.limits, min_range_mm=stroke.min_sweep_mm(opts.stroke),
                                          min_stops_mm=stroke.min_stops_mm(opts.stroke))
    if opts.anchor_mm is None:
        opts.anchor_mm = stroke.gauge_anchor_mm(opts.stroke)
    return opts


def bringup_record(path):
    """Where the bringup record of calibration file `path` goes."""
    path = Path(path)
    return path.with_name(path.stem + ".bringup.json")


def bringup_done(path, board_name):
    """The record of a passed bringup on board `board_name` beside `path`, or None."""
    try:
        record = json.loads(bringup_record(path).read_text())
    except (OSError, ValueError):
        return None
    return record if record.get("ok") and record.get("board") == board_name else None


def run_bringup(session, rig, prompter, opts, alone, log=None):
    """The bringup step: show, record, and decide whether the calibration may go on."""
    from host.guided.bringup import calibrate_bringup

    log = log or _NoLog()
    log.start(BRINGUP)
    outcome = calibrate_bringup(session, rig, prompter, opts)
    log.done(outcome, accepted=outcome.ok)
    prompter.say("[bringup] results:")
    for line in outcome.lines:
        prompter.say("  " + line)
    record = bringup_record(opts.out)
    tmp = record.with_name(record.name + ".tmp")
    tmp.write_text(json.dumps(outcome.sections["bringup"], indent=1) + "\n")
    tmp.replace(record)
    prompter.say("  recorded in %s" % record)
    if outcome.ok:
        return outcome
    if alone or prompter.yes or not prompter.accept("Bringup found problems (above). Calibrate anyway?"):
        raise StepRefused("bringup found %d problem(s): fix them (see above) and run host calibrate bringup again"
                        % len(outcome.sections["bringup"]["problems"]))
    return outcome


def _trim_friction(session, rig, prompter, opts, outcome, cal, board_name):
    """The accepted force step trimmed in closed loop (host/guided/friction_trim.py): its friction,
    then F0 by what the holds leave (host/fitting/force_correction.py); the sections rewritten and
    flashed again, the lines added to the step's. The identified calibration is already written
    and on the board, so a trim that cannot be done leaves it as it is and says why."""
    from host.calibration.file import now_iso
    from host.guided.friction_trim import CHECK_FRACTIONS, check_rms_mn, keep_correction, trim_friction, trimmed_sections

    identified = (outcome.sections.get("friction") or {})
    # h = 0 is trimmed too: the open-loop levels of a light, lively block can read no friction at
    # all where the running loop meets 0.1 N (202611281102, docs/robustness.md)
    if not (opts.trim and opts.friction and "friction_n" in identified):
        return
    if not opts.flash:
        outcome.lines.append("force: friction not trimmed (--no-flash: force mode needs the calibration on the board)")
        prompter.say("  " + outcome.lines[-1])
        return
    prompter.say("[force] friction trim: force-mode holds against the gauge, the estimate compared with it")
    try:
        trim = trim_friction(session, rig, prompter, opts, outcome.data)
    except UserError as exc:
        outcome.lines.append("force: friction not trimmed (%s); h stays %.3f N as identified" % (exc, identified["friction_n"]))
        prompter.say("  " + outcome.lines[-1])
        return
    identified_doc = cal.read()
    sections, lines = trimmed_sections(identified_doc, trim)

    date = now_iso()  # once: the same sections make the same file, and the same CRC on the board

    def install(chosen):  # one write: F0 and its inverse must not disagree on the board
        cal.set_sections(chosen, board=board_name, date=date)
        session.flash(cal.path)

    if "force" in sections:  # F0 corrected: kept only if the check's holds say it helps
        install(sections)
        with_mn = check_rms_mn(session, rig, prompter, opts, outcome.data, "F0 check, corrected")
        # the trimmed h with F0 and its inverse as identified
        h_only = dict((name, identified_doc.get(name)) for name in sections if name != "friction")
        h_only["friction"] = sections["friction"]
        install(h_only)
        without_mn = check_rms_mn(session, rig, prompter, opts, outcome.data, "F0 check, as identified")
        figures = "rms estimate - gauge %s mN with it, %s mN without, at %s of each side's range" % (
            "-" if with_mn is None else "%.0f" % with_mn, "-" if without_mn is None else "%.0f" % without_mn,
            "/".join("%g" % f for f in CHECK_FRACTIONS))
        if keep_correction(with_mn, without_mn):
            install(sections)
            lines.append("force: F0 correction checked in closed loop and kept (%s)" % figures)
        else:
            sections = h_only
            lines.append("force: F0 correction checked in closed loop and NOT kept, F0 stays as identified (%s)" % figures)
    elif sections:
        install(sections)
    if sections:
        outcome.sections.update(sections)
        outcome.data["friction_n"] = trim.friction_n
    for line in lines:
        outcome.lines.append(line)
        prompter.say("  " + line)


@dataclass(frozen=True)
class Step:
    """A calibration step: `measure(session, rig, prompter, opts, path)` -> StepOutcome (nothing
    written), and `after(session, rig, prompter, opts, outcome, cal, board_name)`, what follows once
    its sections are written and flashed (the force step's friction trim)."""

    name: str
    measure: object
    after: object = None


def step_registry():
    """{name: Step} of the calibration steps, in STEPS' order (their modules imported now)."""
    from host.guided.assembly_calibration import calibrate_assembly
    from host.guided.force_calibration import calibrate_force
    from host.guided.gain_sweep import calibrate_gain
    from host.guided.pot_calibration import calibrate_pots

    return {"pots": Step("pots", lambda session, rig, prompter, opts, path: calibrate_pots(session, rig, prompter, opts)),
            "assembly": Step("assembly", calibrate_assembly),
            "gain": Step("gain", calibrate_gain),
            "force": Step("force", calibrate_force, after=_trim_friction)}


class _NoLog:
    """The run log's face when there is none (RunLog: start, done)."""

    def start(self, step):
        pass

    def done(self, outcome, accepted):
        pass


def _accepted(prompter, step, outcome, log):
    """Show the step's results and ask: True to write it, False when the person declines;
    StepRefused when there is nothing to write or its checks failed under --yes."""
    prompter.say("[%s] results:" % step)
    for line in outcome.lines:
        prompter.say("  " + line)
    for png in outcome.plots:
        prompter.say("  plot: %s" % png)
    if not outcome.sections:
        log.done(outcome, accepted=False)
        raise StepRefused("%s step produced no calibration: fix what the checks say and run it again" % step)
    question = "Accept the %s calibration?" % step
    if not outcome.ok:
        question = "Some checks FAILED (see above). Accept the %s calibration anyway?" % step
        if prompter.yes:
            log.done(outcome, accepted=False)
            raise StepRefused("%s step failed its checks (see above); not accepted under --yes" % step)
    if not prompter.accept(question):
        prompter.say("  %s not accepted: the calibration file keeps its previous %s sections" % (step, step))
        log.done(outcome, accepted=False)
        return False
    return True


def run_steps(session, rig, prompter, steps, opts, log=None):
    """Run `steps`; returns {step: StepOutcome} of the accepted ones. `log` (host.guided.run_log.
    RunLog) records each step as it finishes."""
    log = log or _NoLog()
    path = Path(opts.out)
    cal = CalibrationFile(path)
    follow_the_actuator(opts, session)
    if rig is not None:
        rig.ends = tuple("%g mm" % v for v in opts.stroke)
    board_name = session.board["name"]
    accepted = {}
    if BRINGUP in steps:
        steps = tuple(s for s in steps if s != BRINGUP)
        accepted[BRINGUP] = run_bringup(session, rig, prompter, opts, alone=not steps, log=log)
        board_name = session.board["name"]
        if not steps:
            return accepted
    full = tuple(steps) == STEPS
    if "pots" not in steps and not path.exists():
        raise UserError("%s does not exist: calibrate the pots first (host calibrate pots)" % path)

    def keep_previous():
        backup = cal.keep_previous()
        if backup is not None:
            prompter.say("  kept the previous calibration as %s" % backup)

    if path.exists():
        try:
            cal.read()
        except UserError:
            if not full:  # a step updates the file's other sections: refuse before measuring
                raise
            keep_previous()  # a full run replaces it all; the unreadable file is kept aside
    registry = step_registry()
    for name in steps:
        step = registry[name]
        log.start(name)
        outcome = step.measure(session, rig, prompter, opts, path)
        if not _accepted(prompter, name, outcome, log):
            continue
        keep_previous()
        cal.set_sections(outcome.sections, board=board_name, new_pots=full)
        if full and cal.left_out:
            warn("%s measured through the old pot curves: left out of %s (kept in %s)"
                 % (", ".join(cal.left_out), path, cal.backup))
        elif cal.left_out:
            warn("the end stops measured with the old pot curves are left out of %s (the soft limits are the "
                 "stroke parameters alone until a pots step measures them again)" % path)
        prompter.say("  wrote %s to %s" % (", ".join(outcome.sections), path))
        if opts.flash:
            session.flash(path)
        if step.after is not None:
            step.after(session, rig, prompter, opts, outcome, cal, board_name)
        accepted[name] = outcome
        log.done(outcome, accepted=True)
    return accepted
