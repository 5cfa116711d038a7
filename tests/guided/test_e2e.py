"""Guided calibration end to end on the virtual board (real firmware on MicroPython behind a pty).

One shortened full run (faster sweeps, one force round) is shared by the tests of this module:
every section is written and verifies, the firmware reports the file's CRC after each flash, and
closed-loop position errors measured by the reference sensor shrink against the nominal 2-point
pot calibration. A rig fault (a lifted wiper) stops the pot step with the firmware's one-line reason.
"""

import json
import re

import numpy as np
import pytest

from host.calibration.file import read_calibration
from host.cli import build_parser
from host.commands.calibrate import calibrate
from host.errors import UserError

SHORT = ["--yes", "--duty", "3000", "--rounds", "1", "--levels", "4"]


@pytest.fixture(scope="module")
def full_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("cal") / "calibration.json"
    said = []
    args = build_parser().parse_args(["calibrate", "--port", "sim", "--out", str(out)] + SHORT)
    accepted = calibrate(args, say=said.append)
    return out, accepted, said


def test_every_step_is_accepted_written_and_verified(full_run):
    out, accepted, said = full_run
    # a first full run checks the wiring first (bringup), and records it beside the file
    assert list(accepted) == ["bringup", "pots", "assembly", "gain", "force"]
    assert json.loads(out.with_name(out.stem + ".bringup.json").read_text())["ok"]
    doc = read_calibration(out)  # CRC and every section checked by the firmware's own parser
    for name in ("pot1", "pot2", "df", "deformation_offset", "deformation_gain", "force", "force_inverse", "friction", "stroke", "force_range"):
        assert doc[name] and doc[name]["fixed"], name
    # pot 2 of boards/sim.json is mounted true: what is left of its slope is its curve's (a few %)
    lo, hi = doc["deformation_gain"]["fit"]["gain_range"]
    assert 0.95 < lo <= 1.0 <= hi < 1.05, (lo, hi)
    # the board takes force targets within what the force step held on each side (about 17.9 N here)
    lo, hi = doc["force_range"]["range_n"]
    assert -20.0 < lo < -15.0 and 15.0 < hi < 20.0 and doc["force_range"]["fit"]["assumed"] == [], doc["force_range"]
    # positions are measured from the block's end stops (their middle is 30 mm): pot 2 of
    # boards/sim.json is mounted true, so the stops come out at 0 and 60 mm of D2
    lo, hi = doc["stroke"]["end_stops_mm"]
    assert abs(lo) < 0.15 and abs(hi - 60.0) < 0.15, (lo, hi)
    for pot in ("pot1", "pot2"):  # --model auto: the cheapest firmware curve near the noise floor
        assert doc[pot]["model"] in ("bcm", "pwl") and doc[pot]["fit"]["rms"] < 0.05, doc[pot]["fit"]
    assert doc["df"]["fit"]["order"] >= 4  # the paper's quartic, or higher by cross-validation
    crcs = [int(m.group(1), 16) for m in map(re.compile(r"firmware runs calibration crc ([0-9a-f]{8})").search, said) if m]
    trim = doc["friction"]["fit"]
    assert trim["trim_holds"] >= 8 and abs(doc["friction"]["friction_n"] - trim["identified_n"]) < 0.5 * trim["identified_n"]
    assert any("friction trimmed in closed loop" in line for line in said)
    # F0 corrected by what the holds left, then checked in closed loop against the identified F0
    assert any("F0 corrected in closed loop" in line for line in said), [x for x in said if "F0" in x]
    checked = [line for line in said if "F0 correction checked in closed loop" in line]
    assert len(checked) == 1, [x for x in said if "F0" in x]
    # one flash per step, each a new file; after the force step's trim, the corrected F0 and the
    # identified one for the check, and the corrected one once more when it is kept
    if "and kept" in checked[0]:  # a table, its inverse the same knots swapped
        assert len(crcs) == 7 and len(set(crcs)) == 6 and crcs[-1] == crcs[-3], crcs
        assert doc["force"]["kind"] == doc["force_inverse"]["kind"] == "pwl" and doc["force"]["fit"]["identified"]
        assert doc["force"]["knots_in"] == doc["force_inverse"]["knots_out"]
    else:
        assert "NOT kept" in checked[0] and len(crcs) == 6 and len(set(crcs)) == 6, crcs
        assert "correction_mn" not in doc["force"]["fit"]
    assert crcs[-1] == json.loads(out.read_text())["crc32"]
    for png in ("calibration-pot1.png", "calibration-pot2.png", "calibration-df.png", "calibration-gain.png",
                "calibration-force.png"):
        assert (out.parent / png).stat().st_size > 10000


def test_fits_are_sane(full_run):
    _, accepted, _ = full_run
    pots = accepted["pots"].data
    for pot in ("pot1", "pot2"):
        assert pots[pot]["fit"].rms < 0.2  # mm; BCM-3 on knee pots, far below the ~2 mm of a straight line
        assert pots[pot]["ref"].max() - pots[pot]["ref"].min() > 55
    df = accepted["assembly"].data["stats"]
    assert df["peak_before_mm"] > 3.0  # the simulated assembly error is ~4.6 mm at the ends
    assert df["peak_after_mm"] < df["peak_before_mm"] / 5
    force = accepted["force"].data
    cf = force["coeffs_f"]
    assert 10.0 < cf[-2] < 15.0  # stiffness near 12.4 N/mm
    assert force["sides"] == ("high", "low") and force["d_mm"].min() < -0.5 < 0.5 < force["d_mm"].max()
    # the block's friction (0.3 N Coulomb in the model) is identified, and taking it out of the
    # fit shrinks the residual several-fold
    assert 0.1 < force["friction_n"] < 0.4 and force["rms_n"] < force["rms_plain_n"] / 2, force


def test_closed_loop_error_is_smaller_after_calibration(full_run, tmp_path):
    from host.experiments import displacement, variants
    from host.guided.prompts import Prompter
    from host.guided.rig import Rig, reference_scale
    from host.guided.session import Session

    out, accepted, _ = full_run
    nominal = variants.write_nominal(tmp_path / "nominal.json", out, accepted["pots"].data, 12)
    prompter = Prompter(yes=True, out=lambda s: None)
    with Session("sim", None, out, say=lambda s: None) as session:
        scale = reference_scale(session.actuator)
        rig = Rig(prompter, session.virtual)
        zero = displacement.zero_at_stops(session, rig, scale)
        after = displacement.run_targets(session, rig, scale, zero, targets=(3, 30, 57))
        session.flash(nominal)
        before = displacement.run_targets(session, rig, scale, zero, targets=(3, 30, 57))
    assert all(r["settled"] for r in after)
    e_after, e_before = displacement.max_error(after), displacement.max_error(before)
    assert e_after < 0.5 and e_after < e_before / 3, (e_before, e_after)


def test_force_step_reads_the_gauge_channel(full_run, tmp_path):
    # --gauge adc: the gauge's analog output on the board's reference input, read through the
    # firmware's telemetry instead of the gauge's display
    import shutil

    out, accepted, _ = full_run
    cal = tmp_path / "calibration.json"
    shutil.copyfile(out, cal)
    said = []
    args = build_parser().parse_args(["calibrate", "force", "--port", "sim", "--out", str(cal), "--gauge", "adc",
                                      "--gauge-sides", "high"] + SHORT)
    force = calibrate(args, say=said.append)["force"].data
    assert any("analog output to the board's reference input" in line for line in said)
    assert 0.1 < force["friction_n"] < 0.4 and force["rms_n"] < force["rms_plain_n"] / 2, force
    display = accepted["force"].data  # the same spring, read from the display in the full run
    for d in (-1.0, -0.5):
        assert abs(np.polyval(force["coeffs_f"], d) - np.polyval(display["coeffs_f"], d)) < 0.25
    assert read_calibration(cal)["friction"]["fixed"][0] == round(force["friction_n"] * 1000)


def test_a_lifted_wiper_is_refused_under_yes(tmp_path):
    from host.guided.flow import Options, run_steps
    from host.guided.prompts import Prompter
    from host.guided.rig import Rig, reference_scale
    from host.guided.session import Session

    said = []
    prompter = Prompter(yes=True, out=said.append)
    opts = Options(out=tmp_path / "c.json", out_dir=tmp_path, duty=3000, flash=False)
    with Session("sim", None, None, say=said.append) as session:
        opts.ref_scale = reference_scale(session.actuator)
        rig = Rig(prompter, session.virtual)
        rig.state["fault"] = {"channel": "pot2", "rail": "low"}
        with pytest.raises(UserError, match=r"pot2 reads 0 at the low rail \(wiper lifted"):
            run_steps(session, rig, prompter, ("pots",), opts)
    assert not (tmp_path / "c.json").exists() or "pot2" not in read_calibration(tmp_path / "c.json")
