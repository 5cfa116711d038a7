"""Saved controller parameters: the file format and its atomic save (firmware/saved_params.py, on
CPython and the MicroPython unix port), and `host params` on the virtual board: list, read, set,
refuse bad values without setting anything, --save, loaded at boot, restored by the watchdog,
a damaged file named in status."""

import json
import os
import time

import pytest

from firmware import records, saved_params
from firmware.records import FileRecord
from firmware.protocol import PARAMS
from host import cli
from host.link.board_client import BoardClient
from host.link.virtual_board import VirtualBoard
from testkit.interpreters import run_micropython


DEFAULTS = [row[1] for row in PARAMS]


def test_save_then_load_gives_the_values_back(tmp_path):
    path = str(tmp_path / "params.txt")
    values = list(DEFAULTS)
    values[0] = 900
    saved_params.save(FileRecord(path), PARAMS, values)
    got, why = saved_params.load(FileRecord(path), PARAMS)
    assert why is None and got == dict(enumerate(values))
    assert not os.path.exists(path + ".new")


@pytest.mark.parametrize("damage, reason", [
    (lambda t: t.replace("kp_pos 900", "kp_pos 901"), "CRC"),
    (lambda t: t.replace("lsea-kit params 1", "lsea-kit params 2"), "not an lsea-kit params file"),
    (lambda t: t[: len(t) // 2], "CRC"),
    (lambda t: "", "not an lsea-kit params file"),
])
def test_a_damaged_file_is_refused_whole_with_the_reason(tmp_path, damage, reason):
    path = tmp_path / "params.txt"
    values = list(DEFAULTS)
    values[0] = 900
    saved_params.save(FileRecord(str(path)), PARAMS, values)
    path.write_text(damage(path.read_text()))
    got, why = saved_params.load(FileRecord(str(path)), PARAMS)
    assert got == {} and reason in why


def _params_file(path, lines):
    """A params file with a right CRC around `lines` (save itself refuses to write these)."""
    import binascii

    body = "\n".join([saved_params.HEADER] + lines) + "\n"
    with open(path, "w") as f:
        f.write(body + "crc %08x\n" % (binascii.crc32(body.encode()) & 0xFFFFFFFF))


def test_a_value_outside_the_table_or_an_unknown_name_is_refused(tmp_path):
    table = [("a", 1, 0, 10, "x"), ("b", 2, 0, 10, "x")]
    path = str(tmp_path / "p.txt")
    _params_file(path, ["a 5", "b 11"])
    assert "outside 0..10" in saved_params.load(FileRecord(path), table)[1]
    _params_file(path, ["a 1", "b 2", "c 0"])
    assert "unknown parameter" in saved_params.load(FileRecord(path), table)[1]
    with pytest.raises(ValueError, match="outside 0..10"):  # nor does save write such a file
        saved_params.save(FileRecord(path), table, [5, 11])


def test_no_file_means_defaults_and_no_complaint(tmp_path):
    assert saved_params.load(FileRecord(str(tmp_path / "none.txt")), PARAMS) == ({}, None)
    assert saved_params.load(None, PARAMS) == ({}, None)


def test_a_filesystem_that_cannot_rename_onto_a_file_still_saves(tmp_path, monkeypatch):
    """FAT: rename onto an existing file fails, so the old file is removed first; a power cut
    right then leaves only PATH.new, which load takes."""
    path = str(tmp_path / "params.txt")
    saved_params.save(FileRecord(path), PARAMS, DEFAULTS)
    real_rename = os.rename

    def fat_rename(src, dst):
        if os.path.exists(dst):
            raise OSError(17, "EEXIST")
        real_rename(src, dst)

    monkeypatch.setattr(records.os, "rename", fat_rename)
    values = list(DEFAULTS)
    values[1] = 20
    saved_params.save(FileRecord(path), PARAMS, values)
    assert saved_params.load(FileRecord(path), PARAMS)[0][1] == 20
    # the power cut between the remove and the rename
    monkeypatch.setattr(records.os, "rename", lambda src, dst: (_ for _ in ()).throw(OSError(5, "EIO")))
    values[1] = 30
    with pytest.raises(OSError):
        saved_params.save(FileRecord(path), PARAMS, values)
    assert not os.path.exists(path) and os.path.exists(path + ".new")
    assert saved_params.load(FileRecord(path), PARAMS)[0][1] == 30


def test_the_unix_port_reads_what_cpython_wrote_and_the_other_way(tmp_path):
    a, b = str(tmp_path / "a.txt"), str(tmp_path / "b.txt")
    values = list(DEFAULTS)
    values[2] = 3000
    saved_params.save(FileRecord(a), PARAMS, values)
    out = run_micropython(
        "from firmware import saved_params\nfrom firmware.protocol import PARAMS\n"
        "from firmware.records import FileRecord\n"
        "got, why = saved_params.load(FileRecord(%r), PARAMS)\nprint(why, got[2])\n"
        "v = [r[1] for r in PARAMS]\nv[3] = 4000\nsaved_params.save(FileRecord(%r), PARAMS, v)\n" % (a, b)).stdout.split()
    assert out == ["None", "3000"]
    assert saved_params.load(FileRecord(b), PARAMS)[0][3] == 4000


# --- host params on the virtual board ---------------------------------------------------------

def params_json(capsys, port):
    capsys.readouterr()
    assert cli.main(["params", "--port", port, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def test_list_read_set_and_refuse(model_calibration, capsys):
    with VirtualBoard(calibration=model_calibration) as vb:
        port = vb.path
        table = params_json(capsys, port)
        assert [(p["name"], p["default"], p["min"], p["max"], p["unit"]) for p in table["params"]] == [tuple(r) for r in PARAMS]
        assert table["saved"] is None and table["file_error"] is None
        assert cli.main(["params", "--port", port]) == 0
        text = capsys.readouterr().out
        assert "kp_pos" in text and "duty/256 per um" in text and "0..65535" not in text.split("kp_pos")[0]
        assert cli.main(["params", "--port", port, "kp_pos=900", "slew=400"]) == 0
        out = capsys.readouterr().out
        assert "kp_pos = 900" in out and "not saved" in out
        assert cli.main(["params", "--port", port, "kp_pos"]) == 0
        assert capsys.readouterr().out.strip() == "kp_pos 900 duty/256 per um"
        for bad, why in [("kp_pos=nan", "whole number"), ("kp_pos=1e3", "whole number"), ("kp_pos=", "whole number"),
                         ("slew=-1", "outside the firmware's limits"), ("slew=99999999999", "outside"),
                         ("kpos=1", "unknown parameter")]:
            assert cli.main(["params", "--port", port, "ki_pos=99", bad]) == 2, bad
            err = capsys.readouterr().err
            assert why in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
        values = {p["name"]: p["value"] for p in params_json(capsys, port)["params"]}
        assert values["ki_pos"] == dict((r[0], r[1]) for r in PARAMS)["ki_pos"]  # nothing set by a refused command
        assert cli.main(["params", "--port", port, "--defaults"]) == 0
        assert all(p["value"] == p["default"] for p in params_json(capsys, port)["params"])


def test_saved_values_survive_a_restart_and_are_what_the_watchdog_restores(model_calibration, capsys):
    with VirtualBoard(calibration=model_calibration) as vb:
        port = vb.path
        assert cli.main(["params", "--port", port, "kp_pos=900", "--save"]) == 0
        out = capsys.readouterr().out
        assert "saved on the board (params.txt, loaded at boot): kp_pos=900" in out, out
        with BoardClient(port) as board:
            board.soft_reset()
        table = params_json(capsys, port)
        assert table["saved"] == {"kp_pos": 900}
        assert {p["name"]: p["value"] for p in table["params"]}["kp_pos"] == 900
        assert cli.main(["status", "--port", port]) == 0
        assert "kp_pos=900" in capsys.readouterr().out
        # a value set (not saved) during a hold whose host goes silent returns to the saved one
        assert cli.main(["params", "--port", port, "kp_pos=1000"]) == 0
        assert cli.main(["move", "--port", port, "--to", "25", "--hold"]) == 0
        time.sleep(1.5)
        with BoardClient(port) as board:
            status = board.call("status")
            assert status["faults"] == ["host_timeout"] and "kp_pos" in status["params_restored"]
            assert board.call("get", "kp_pos") == 900
            board.call("reset")
        # saving is refused while the motor runs
        with BoardClient(port) as board:
            board.call("status")
            board.call("mode", "open_loop")
            with pytest.raises(Exception, match="stop first"):
                board.call("save")
            board.call("stop")


def test_a_damaged_saved_file_is_named_and_the_defaults_stand(model_calibration, capsys):
    with VirtualBoard(calibration=model_calibration) as vb:
        port = vb.path
        assert cli.main(["params", "--port", port, "slew=300", "--save"]) == 0
        path = vb.root / "params.txt"
        path.write_text(path.read_text().replace("slew 300", "slew 301"))
        with BoardClient(port) as board:
            board.soft_reset()
        table = params_json(capsys, port)
        assert "CRC" in table["file_error"] and table["saved"] is None
        assert {p["name"]: p["value"] for p in table["params"]}["slew"] == dict((r[0], r[1]) for r in PARAMS)["slew"]
        assert cli.main(["params", "--port", port]) == 0
        assert "saved parameters not loaded at boot" in capsys.readouterr().out


def test_a_save_whose_file_does_not_read_back_is_refused_and_keeps_the_old_one(tmp_path, monkeypatch):
    """A flash that stores something else than was written (here every '9' becomes '8'): the
    save says so, and the file in use keeps the values saved before."""
    import builtins

    path = str(tmp_path / "params.txt")
    values = list(DEFAULTS)
    values[0] = 900
    saved_params.save(FileRecord(path), PARAMS, values)
    before = open(path).read()

    class Corrupting:
        def __init__(self, f):
            self.f = f

        def write(self, text):
            return self.f.write(text.replace("9", "8"))

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.f.close()

    def corrupting_open(name, mode="r", *a, **k):
        f = builtins.open(name, mode, *a, **k)
        return Corrupting(f) if "w" in mode else f

    monkeypatch.setattr(records, "open", corrupting_open, raising=False)
    values[0] = 990
    with pytest.raises(ValueError, match="did not read back"):
        saved_params.save(FileRecord(path), PARAMS, values)
    assert open(path).read() == before and not os.path.exists(path + ".new")
    assert saved_params.load(FileRecord(path), PARAMS)[0][0] == 900
