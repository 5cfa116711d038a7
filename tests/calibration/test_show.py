"""`host show`: a calibration file in words, and two compared as the board would compute them."""

import json

from host import cli
from host.calibration.file import force_range_section, poly_section, write_calibration

from tests.calibration.test_calibration_file import full_document


def write(path, **changes):
    doc = full_document()
    doc.update(changes)
    write_calibration(path, doc)
    return path


def test_show_says_what_the_file_holds(tmp_path, capsys):
    path = write(tmp_path / "a.json", force=poly_section([0.65, 12.37, 2.08], (-2.0, 6.0), 1000, 1000, ("um", "mN")))
    assert cli.main(["show", str(path)]) == 0
    out = capsys.readouterr().out
    for text in ("board pico", "pot ids: pot1=pot-A, pot2=pot-B", "pot1: bcm", "pot2: lut", "pwl on the board", "codes 0..4095",
                 "df: Df_hat(D1)", "force: F0(d)", "um -> ", " mN", "force_inverse: none", "friction: none", "CRC "):
        assert text in out, (text, out)
    assert "force range: not recorded (force mode takes any target within +-200 N)" in out
    assert cli.main(["show", str(path), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["board"] == "pico"


def test_show_says_which_force_targets_the_board_takes(tmp_path, capsys):
    held = force_range_section(-12.4, 12.4, {"measured": [-1], "assumed": [1]})
    a = write(tmp_path / "a.json", force_range=held)
    assert cli.main(["show", str(a)]) == 0
    out = capsys.readouterr().out
    assert "force range: -12.40 .. +12.40 N (what the force step held; force mode refuses targets beyond); the positive " \
           "side was not measured" in out, out
    b = write(tmp_path / "b.json", force_range=force_range_section(-15.0, 14.0))
    assert cli.main(["show", str(a), str(b)]) == 0
    assert "force range: -12.40..+12.40 N | -15.00..+14.00 N" in capsys.readouterr().out


def test_show_compares_two_files_as_the_board_computes_them(tmp_path, capsys):
    a = write(tmp_path / "a.json")
    assert cli.main(["show", str(a), str(write(tmp_path / "same.json"))]) == 0
    assert capsys.readouterr().out.strip().endswith("the same calibration")
    doc = full_document()
    pot2 = dict(doc["pot2"])
    n = pot2["fixed"][0]
    pot2["fixed"] = pot2["fixed"][: 2 + n] + [v + (40 if i == n // 2 else 0) for i, v in enumerate(pot2["fixed"][2 + n:])]
    b = write(tmp_path / "b.json", pot2=pot2, board="sim")
    assert cli.main(["show", str(a), str(b)]) == 0
    out = capsys.readouterr().out
    assert "board: pico | sim" in out and "pot1: the same on the board" in out
    assert "pot2: lut | lut; positions differ by 40.0 um at most" in out, out


def test_a_bad_file_is_one_line(tmp_path, capsys):
    bad = tmp_path / "bad.json"
    bad.write_text("{}")
    assert cli.main(["show", str(bad)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: calibration file") and len(err.strip().splitlines()) == 1
