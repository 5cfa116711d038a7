"""`host fit` from the command line: JSON fields, plots, calibration files, one-line errors."""

import json
import subprocess
import sys

import numpy as np
import pytest

from host.cli import main
from host.fitting.example_sweep import DEFAULT_PATH

EXAMPLE = str(DEFAULT_PATH)


def _json(capsys, *argv):
    assert main(["fit", *argv, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def test_json_has_the_promised_fields(capsys):
    out = _json(capsys, EXAMPLE, "--model", "bcm")
    for key in ("model", "order", "rms", "max_abs", "monotone", "noise_floor", "n_samples", "n_excluded", "fit_seconds"):
        assert key in out
    assert out["model"] == "bcm" and out["order"] == 3 and out["monotone"] is True
    assert out["n_samples"] + out["n_excluded"] == out["n_input"] == 1800
    assert out["exclusions"]["clipped_low"] > 0 and out["exclusions"]["clipped_high"] > 0
    assert 0 < out["noise_floor"] < out["rms"] < 0.5
    assert 0 < out["fit_seconds"] <= out["total_seconds"]
    assert len(out["coefficients"]["handles"]) == 4 and out["coefficients"]["weights"][0] == 1.0
    # the example's backlash (50 um between directions) is found: +-25 um
    assert abs(out["hysteresis"] - 0.025) < 0.004


def test_summary_is_readable(capsys):
    assert main(["fit", EXAMPLE, "--model", "bcm", "--order", "2"]) == 0
    text = capsys.readouterr().out
    assert "model: bcm order 2" in text and "rms / noise floor" in text and "monotone: yes" in text


def test_paper_bounds_option(capsys):
    out = _json(capsys, EXAMPLE, "--model", "bcm", "--bounds", "paper")
    assert min(out["coefficients"]["handles"]) >= 0 and max(out["coefficients"]["handles"]) <= 60


def test_plot_writes_a_png(tmp_path, capsys):
    png = tmp_path / "fit.png"
    out = _json(capsys, EXAMPLE, "--plot", str(png))
    assert out["plot"] == str(png)
    data = png.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10000


def test_auto_reports_a_reason(capsys):
    out = _json(capsys, EXAMPLE, "--model", "auto")
    assert out["model"] in ("bcm", "pwl") and out["n_params"] <= 64
    assert "cross-validated" in out["auto_reason"] and "floor" in out["auto_reason"]


def test_without_model_fit_chooses_as_calibrate_does(capsys):
    """A newcomer's `host fit SWEEP.csv` makes the curve a calibration would: the default --model
    is calibrate's (auto), and the fit is the one --model auto makes."""
    from host.cli import build_parser

    def default_model(*argv):
        return build_parser().parse_args(list(argv)).model

    assert default_model("fit", EXAMPLE) == default_model("calibrate") == "auto"
    chosen = _json(capsys, EXAMPLE)
    auto = _json(capsys, EXAMPLE, "--model", "auto")
    assert chosen["auto_reason"] == auto["auto_reason"]
    assert (chosen["model"], chosen["order"], chosen["rms"]) == (auto["model"], auto["order"], auto["rms"])


@pytest.mark.parametrize("argv, given", [(["--order", "5"], "--order"), (["--model", "auto", "--bounds", "paper"], "--bounds"),
                                         (["--order", "5", "--bounds", "paper"], "--order and --bounds")])
def test_options_of_a_named_model_are_refused_under_auto(capsys, argv, given):
    """`host fit X --order 5` meant BCM-5 when bcm was the default: under auto it must not be dropped silently."""
    assert main(["fit", EXAMPLE, *argv]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: %s needs a named --model: auto chooses" % given) and err.count("\n") == 1, err


def test_out_writes_a_calibration_the_firmware_accepts(tmp_path, capsys):
    from firmware.calibration import convert, load_calibration
    from host.fitting.rational_bezier import evaluate

    path = tmp_path / "calib.json"
    first = _json(capsys, EXAMPLE, "--model", "bcm", "--out", str(path))
    assert first["calibration"]["adc_bits"] == 12 and path.exists()
    # a lower-degree BCM goes in as the same curve elevated to degree 3; pot1 is kept
    second = _json(capsys, EXAMPLE, "--model", "bcm", "--order", "2", "--out", str(path), "--pot", "pot2")
    cal = load_calibration(str(path))
    assert cal.crc == second["calibration"]["crc32"]
    assert cal.pot1[0] == "bcm3" and cal.pot2[0] == "bcm3"
    for fit, (kind, k) in ((first, cal.pot1), (second, cal.pot2)):
        for code in (0, 150, 2048, 3950, 4095):
            want_um = 1000 * evaluate(fit["coefficients"], code)
            assert abs(convert(kind, code, k) - want_um) < 8  # within the export's half-LSB bound


def test_out_records_board_and_pot_identity(tmp_path, capsys):
    from firmware.calibration import load_calibration
    from host.calibration.file import read_calibration

    path = str(tmp_path / "calib.json")
    out = _json(capsys, EXAMPLE, "--out", path, "--board", "bench-rig-1", "--pot-id", "P1-0042")
    assert out["calibration"]["board"] == "bench-rig-1" and out["calibration"]["pot_id"] == "P1-0042"
    _json(capsys, EXAMPLE, "--out", path, "--pot", "pot2", "--pot-id", "P2-0007")
    _json(capsys, EXAMPLE, "--model", "bcm", "--order", "2", "--out", path)  # refit pot1: board and id stay
    doc = read_calibration(path)
    assert doc["board"] == "bench-rig-1" and doc["pots"] == {"pot1": "P1-0042", "pot2": "P2-0007"}
    assert doc["pot1"]["pot_id"] == "P1-0042" and doc["pot2"]["pot_id"] == "P2-0007"
    assert doc["pot1"]["order"] == 3 and "elevated" in " ".join(doc["pot1"]["fit"]["notes"])
    cal = load_calibration(path)  # the firmware reads the same identity
    assert cal.board == "bench-rig-1" and cal.pots == doc["pots"]


def _bad(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text)
    return str(p)


BAD_FILES = {
    "empty.csv": "",
    "header_only.csv": "raw,reference\n",
    "no_reference.csv": "raw,pos\n1,2\n",
    "text.csv": "raw,reference\n1,2\n3,four\n",
    "few.csv": "raw,reference\n" + "".join("%d,%d\n" % (i * 400, i) for i in range(10)),
    "narrow.csv": "raw,reference\n" + "".join("%d,%d\n" % (2000 + i, i) for i in range(50)),
}


@pytest.mark.parametrize("name", sorted(BAD_FILES))
def test_bad_input_exits_2_with_one_line(tmp_path, capsys, name):
    assert main(["fit", _bad(tmp_path, name, BAD_FILES[name])]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and "\n" not in err


def test_missing_file_and_bad_order(tmp_path, capsys):
    assert main(["fit", str(tmp_path / "missing.csv")]) == 2
    assert "no sweep file at" in capsys.readouterr().err
    assert main(["fit", EXAMPLE, "--model", "bcm", "--order", "0"]) == 2
    assert "--order" in capsys.readouterr().err


def test_out_onto_an_existing_calibration_keeps_the_previous_one_beside_it(tmp_path, capsys):
    path = tmp_path / "calib.json"
    _json(capsys, EXAMPLE, "--model", "bcm", "--out", str(path))
    before = path.read_bytes()
    assert list(tmp_path.glob("calib.json.*.bak")) == []  # nothing to keep the first time
    _json(capsys, EXAMPLE, "--model", "bcm", "--order", "2", "--out", str(path))  # replaces pot1
    _json(capsys, EXAMPLE, "--model", "bcm", "--order", "1", "--out", str(path))  # twice in one second
    kept = {k.name: k.read_bytes() for k in tmp_path.glob("calib.json.*.bak")}
    assert len(kept) == 2 and before in kept.values(), list(kept)
    assert path.read_bytes() not in kept.values()  # each replaced file kept, the present one not


def test_out_with_a_new_pot_curve_leaves_out_the_old_end_stops_and_says_so(tmp_path, capsys):
    """The calibration file's rule (host.calibration.file.CalibrationFile), the same as a `pots`
    step's: end stops measured in the old curve's frame are left out, with a warning."""
    from host.calibration.file import CalibrationFile, stroke_section

    path = tmp_path / "calib.json"
    _json(capsys, EXAMPLE, "--model", "bcm", "--out", str(path))
    CalibrationFile(path).set_sections({"stroke": stroke_section(0.1, 59.9)})
    assert main(["fit", EXAMPLE, "--model", "bcm", "--order", "2", "--out", str(path)]) == 0
    assert "stroke" not in CalibrationFile(path).read()
    assert "stroke left out of" in capsys.readouterr().err


def test_only_the_calibration_file_object_writes_calibration_files():
    """Issue 27: the host's commands change a calibration file through CalibrationFile alone;
    write_calibration (the atomic write under it) makes whole new documents only for the
    experiments' derived files."""
    import re
    from pathlib import Path

    import host

    root = Path(host.__file__).parent
    allowed = {root / "calibration" / "file.py", root / "experiments" / "variants.py"}
    callers = [str(p.relative_to(root)) for p in root.rglob("*.py")
               if p not in allowed and re.search(r"\bwrite_calibration\(|\bkeep_dated_copy\(.*cal", p.read_text())]
    assert not callers, callers


def test_non_adc_sweep_needs_adc_bits_for_out(tmp_path, capsys):
    raw = np.linspace(0.1, 3.2, 40)
    text = "raw,reference\n" + "".join("%.4f,%.4f\n" % (r, 18 * r) for r in raw)
    assert main(["fit", _bad(tmp_path, "volts.csv", text), "--out", str(tmp_path / "c.json")]) == 2
    assert "--adc-bits" in capsys.readouterr().err


@pytest.mark.parametrize(
    "argv, fragment",
    [
        (["fit", EXAMPLE, "--order", "abc"], "argument --order: 'abc' is not a whole number"),
        (["fit", EXAMPLE, "--model", "nurbs"], "argument --model: invalid choice"),
        (["fit"], "required: SWEEP.csv"),
        (["compare", EXAMPLE, "--jobs", "two"], "argument --jobs: 'two' is not a whole number"),
        (["fit", EXAMPLE, "--no-such-option"], "unrecognized arguments: --no-such-option"),
        (["no-such-command"], "invalid choice: 'no-such-command'"),
    ],
)
def test_bad_options_are_one_line_and_exit_2(capsys, argv, fragment):
    assert main(argv) == 2
    captured = capsys.readouterr()
    assert captured.err.startswith("error: ") and captured.err.count("\n") == 1 and fragment in captured.err
    assert "usage:" not in captured.err and captured.out == ""


def test_help_still_prints_the_usage(capsys):
    assert main(["fit", "--help"]) == 0
    assert "usage: host fit" in capsys.readouterr().out


def test_full_scale_checks_coverage_of_a_volts_sweep(tmp_path, capsys):
    raw = np.linspace(0.2, 0.6, 40)
    path = _bad(tmp_path, "volts.csv", "raw,reference\n" + "".join("%.4f,%.4f\n" % (r, 18 * r) for r in raw))
    assert main(["fit", path, "--json"]) == 0  # no claim about volts without a full scale
    capsys.readouterr()
    assert main(["fit", path, "--full-scale", "3.3"]) == 2
    err = capsys.readouterr().err
    assert "covers only 0.4 of its full scale 3.3" in err and err.count("\n") == 1


def test_real_console_script(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "host", "fit", EXAMPLE, "--json"], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert "auto_reason" in json.loads(proc.stdout)  # the default, --model auto
    proc = subprocess.run([sys.executable, "-m", "host", "fit", str(tmp_path / "x.csv")], capture_output=True, text=True)
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1 and "Traceback" not in proc.stderr


def test_demo_writes_report_plots_and_calibration(tmp_path, capsys):
    from firmware.calibration import load_calibration

    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert printed.strip().splitlines()[-1] == "report: %s" % (out / "report.md")
    report = (out / "report.md").read_text()
    assert "| paper's BCM | bcm 3 |" in report and "Auto selection:" in report
    for png in ("fit.png", "fit_auto.png"):
        assert (out / png).read_bytes()[:4] == b"\x89PNG"
    cal = load_calibration(str(out / "calibration.json"))
    assert cal.pot1[0] in ("bcm3", "pwl") and cal.pot2[0] == cal.pot1[0]


def _sweep_file(path, raw, ref):
    with open(path, "w") as f:
        f.write("raw,reference\n")
        for r, y in zip(raw, ref):
            f.write("%d,%r\n" % (int(r), float(y)))
    return str(path)


def test_fit_out_refuses_what_cannot_be_a_calibration(tmp_path, capsys):
    """A reference that is not a function of the reading, and one that falls as the reading
    rises (the firmware refuses such a curve at boot): one error line, status 2, no file;
    --force writes them anyway. Numbers near 1e300 are refused with the sweep, --force or not:
    never an inf or NaN in a file."""
    import numpy as np

    from host import cli

    rng = np.random.default_rng(1)
    raw = np.sort(rng.integers(100, 3900, 1500))
    scattered = _sweep_file(tmp_path / "scattered.csv", raw, rng.uniform(0, 60, raw.size))
    falling = _sweep_file(tmp_path / "falling.csv", raw, 60 - raw * 60 / 4000 + rng.normal(0, 0.02, raw.size))
    huge = _sweep_file(tmp_path / "huge.csv", range(100, 3900, 3), [1e300 * r / 4000 for r in range(100, 3900, 3)])
    for sweep, words in ((scattered, "error: not writing"), (scattered, "of the reference's span"),
                         (falling, "pot_invert"), (huge, "beyond")):
        out = tmp_path / "cal.json"
        code = cli.main(["fit", sweep, "--model", "bcm", "--out", str(out), "-q"])
        err = capsys.readouterr().err.strip().splitlines()
        assert code == 2 and len(err) == 1 and words in err[0], err
        assert not out.exists()
    bcm = ["--model", "bcm"]  # a curve --force can write whatever the sweep (auto's table may not export at all)
    assert cli.main(["fit", scattered, *bcm, "--out", str(tmp_path / "forced.json"), "--force"]) == 0
    assert cli.main(["fit", falling, *bcm, "--out", str(tmp_path / "forced-falling.json"), "--force"]) == 0
    code = cli.main(["fit", huge, *bcm, "--out", str(tmp_path / "forced-huge.json"), "--force"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and err[-1].startswith("error: ") and not (tmp_path / "forced-huge.json").exists(), err


@pytest.mark.parametrize("command", [["fit"], ["fit", "--model", "pwl", "--out", "x.json"], ["compare", "--orders", "2-4"]])
def test_numbers_near_1e300_are_one_line_without_warnings(tmp_path, command):
    """In a real process (pytest would swallow numpy's warnings): stderr is the error line alone."""
    import subprocess
    import sys

    huge = _sweep_file(tmp_path / "huge.csv", range(100, 3900, 3), [1e300 * r / 4000 for r in range(100, 3900, 3)])
    args = command[:1] + [huge] + command[1:] + (["--out", str(tmp_path / "cmp")] if command[0] == "compare" else [])
    proc = subprocess.run([sys.executable, "-m", "host", *args], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    err = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(err) == 1 and err[0].startswith("error: ") and "beyond" in err[0], proc.stderr
