"""`host calibrate` never destroys a calibration it has not replaced: nothing is written before
a step is accepted, the previous file is kept under a dated name before the first change, and
an interrupted run leaves the file as the last accepted step left it. The real flow
(host.guided.flow.run_steps) and calibration-file code; the measuring steps are stand-ins that
return sections from the model calibration (or raise, as Ctrl-C or a lost board would)."""

import json

import pytest

from firmware.calibration import load_calibration
from host.calibration.file import read_calibration, write_calibration
from host.guided import flow
from host.guided.outcome import StepOutcome
from testkit.model import model_sections


def _sections():
    cal = model_sections()
    return {
        "pots": {n: dict(cal[n], pot_id="%s-new" % n) for n in ("pot1", "pot2")},
        "assembly": {"df": cal["df"]},
        "gain": {"deformation_gain": cal["deformation_gain"]},
        "force": {n: cal[n] for n in ("force", "force_inverse", "friction")},
    }


class Quiet:
    yes = True

    def __init__(self):
        self.said = []

    def say(self, text):
        self.said.append(text)

    def accept(self, question):
        return True


class Session:
    board = {"name": "sim", "adc_bits": 12}

    def __init__(self):
        self.flashed = []

    def flash(self, path):
        load_calibration(str(path))  # what the firmware would check
        self.flashed.append(path)


@pytest.fixture
def old_file(tmp_path):
    """A complete calibration made earlier (all sections), the file the run must not lose."""
    sec = _sections()
    doc = {"board": "sim", "pots": {"pot1": "old-1", "pot2": "old-2"}, "date": "2026-01-01T00:00:00+00:00"}
    for step in ("pots", "assembly", "gain", "force"):
        doc.update(sec[step])
    doc["pot1"] = dict(doc["pot1"], pot_id="old-1")
    doc["pot2"] = dict(doc["pot2"], pot_id="old-2")
    path = tmp_path / "calibration.json"
    write_calibration(path, doc)
    return path


def _steps(monkeypatch, fail_at=None, failure=None):
    sec = _sections()
    failure = KeyboardInterrupt() if failure is None else failure

    def step(name):
        def run(*a, **k):
            if name == fail_at:
                raise failure
            return StepOutcome(name, sec[name], ["fitted"], [])
        return run

    import host.guided.assembly_calibration as a
    import host.guided.force_calibration as f
    import host.guided.gain_sweep as g
    import host.guided.pot_calibration as p

    monkeypatch.setattr(p, "calibrate_pots", step("pots"))
    monkeypatch.setattr(a, "calibrate_assembly", step("assembly"))
    monkeypatch.setattr(g, "calibrate_gain", step("gain"))
    monkeypatch.setattr(f, "calibrate_force", step("force"))


def _backups(path):
    return sorted(path.parent.glob(path.name + ".*.bak"))


@pytest.mark.parametrize("fail_at", ["pots", "assembly", "gain", "force"])
def test_an_interrupted_full_run_loses_no_section(old_file, monkeypatch, capsys, fail_at):
    before = old_file.read_bytes()
    _steps(monkeypatch, fail_at=fail_at)
    quiet = Quiet()
    with pytest.raises(KeyboardInterrupt):
        flow.run_steps(Session(), None, quiet, flow.STEPS, flow.Options(out=old_file))
    if fail_at == "pots":  # nothing accepted: the file is untouched, no backup needed
        assert old_file.read_bytes() == before and _backups(old_file) == []
        return
    (backup,) = _backups(old_file)
    assert backup.read_bytes() == before  # every old section kept, under a dated name
    now = read_calibration(old_file)
    assert now["pot1"]["pot_id"] == "pot1-new"  # the accepted pots were written
    # Df and force measured through the old curves went with them, unless re-measured here,
    # and the person was told so, in a warning (never silenced) that names the copy
    assert ("df" in now) == (fail_at in ("gain", "force")) and "force" not in now
    assert ("deformation_gain" in now) == (fail_at == "force")
    warned = capsys.readouterr().err
    assert "warning: df, force, force_inverse, friction, deformation_gain measured through the old pot curves" in warned
    assert "(kept in %s)" % backup in warned, warned


def test_a_single_step_keeps_the_previous_file_and_changes_only_its_sections(old_file, monkeypatch):
    before = read_calibration(old_file)
    _steps(monkeypatch)
    flow.run_steps(Session(), None, Quiet(), ("assembly",), flow.Options(out=old_file))
    (backup,) = _backups(old_file)
    assert read_calibration(backup) == before
    now = read_calibration(old_file)
    for name in ("pot1", "pot2", "deformation_gain", "force", "force_inverse", "friction"):
        assert now[name] == before[name], name


def test_a_corrupt_file_is_kept_aside_by_a_full_run_and_refused_by_a_step(tmp_path, monkeypatch):
    from host.errors import UserError

    path = tmp_path / "calibration.json"
    corrupt = '{"format": "lsea-kit calibration", "schema": 1, "crc32": 1, "payload": "{}"}'
    path.write_text(corrupt)
    _steps(monkeypatch, fail_at="pots", failure=AssertionError("measured"))
    with pytest.raises(UserError):  # a single step needs the file's other sections
        flow.run_steps(Session(), None, Quiet(), ("assembly",), flow.Options(out=path))
    assert path.read_text() == corrupt and _backups(path) == []
    _steps(monkeypatch)
    flow.run_steps(Session(), None, Quiet(), flow.STEPS, flow.Options(out=path))
    (backup,) = _backups(path)
    assert backup.read_text() == corrupt
    assert set(read_calibration(path)) >= {"pot1", "pot2", "df", "force", "force_inverse", "friction"}


@pytest.mark.parametrize("fail_at", ["assembly", "gain", "force"])
def test_an_interrupted_run_keeps_what_it_measured_and_says_where_it_stopped(old_file, monkeypatch, fail_at):
    """host calibrate's run log (host/guided/run_log.py): results.json and report.md beside the
    calibration file, rewritten after every step, and on a stop the step and the reason."""
    from host.guided.run_log import RunLog

    _steps(monkeypatch, fail_at=fail_at, failure=RuntimeError("the board stopped answering"))
    log = RunLog(old_file, "host calibrate --port sim")
    with pytest.raises(RuntimeError):
        flow.run_steps(Session(), None, Quiet(), flow.STEPS, flow.Options(out=old_file), log=log)
    log.stop("the board stopped answering")
    results = json.loads(log.json_path.read_text())
    done = [s["step"] for s in results["steps"]]
    assert done == ["pots", "assembly", "gain", "force"][:["assembly", "gain", "force"].index(fail_at) + 1]
    assert all(s["accepted"] and s["lines"] == ["fitted"] for s in results["steps"])
    assert results["stopped"] == {"phase": fail_at, "why": "the board stopped answering"}
    report = log.report_path.read_text()
    assert "Stopped during %s" % fail_at in report and "## pots: accepted (pot1, pot2 written)" in report


def test_new_pot_curves_without_end_stops_drop_the_old_ones(old_file, monkeypatch):
    """A pots step that could not measure the end stops (a manual reference) writes curves in
    the reference's own frame: end stops measured in the old curves' frame would put the soft
    limits in the wrong place, so the file loses them (the backup keeps them)."""
    doc = read_calibration(old_file)
    doc["stroke"] = {"kind": "stroke", "fixed": [120, 59880]}
    write_calibration(old_file, doc)
    _steps(monkeypatch)
    flow.run_steps(Session(), None, Quiet(), ("pots",), flow.Options(out=old_file))
    now = read_calibration(old_file)
    assert now.get("stroke") is None and now["pot1"]["pot_id"] == "pot1-new"
    (backup,) = _backups(old_file)
    assert json.loads(backup.read_text())["payload"]["stroke"]["fixed"] == [120, 59880]


def test_a_calibrate_that_never_started_leaves_no_folder_and_ctrl_c_leaves_a_log(tmp_path, monkeypatch, capsys):
    """No board: one line, status 2, and the --out folders the run would have made are not left
    behind. Ctrl-C before the first step: status 1 and a run log saying so (docs/guided-calibration.md)."""
    from host import cli
    from host.commands import calibrate as command

    out = tmp_path / "new" / "deeper" / "cal.json"
    code = cli.main(["calibrate", "--port", str(tmp_path / "no-such-port"), "--out", str(out), "--yes"])
    assert code == 2 and not (tmp_path / "new").exists(), capsys.readouterr().err

    def interrupted(args, say=print, ask=None, log=None):
        raise KeyboardInterrupt

    monkeypatch.setattr(command, "calibrate", interrupted)
    code = cli.main(["calibrate", "--port", "sim", "--out", str(out), "--yes"])
    err = capsys.readouterr().err
    assert code == 1 and "before its first step" in err, err
    results = json.loads((out.parent / (out.stem + ".results.json")).read_text())
    assert results["stopped"] == {"phase": None, "why": "interrupted (Ctrl-C)"}


def test_two_calibrations_in_one_folder_keep_their_own_plots(tmp_path):
    """A review's two runs in one folder drew over each other's calibration-pot1.png: a plot is
    named after the calibration it belongs to (calibration-pot1.png for calibration.json)."""
    a = flow.Options(out=tmp_path / "left.json", out_dir=tmp_path)
    b = flow.Options(out=str(tmp_path / "right.json"), out_dir=tmp_path)
    assert a.plot_path("pot1") == tmp_path / "left-pot1.png"
    assert b.plot_path("df") == tmp_path / "right-df.png"
    assert flow.Options(out=tmp_path / "calibration.json", out_dir=tmp_path).plot_path("force") == tmp_path / "calibration-force.png"
