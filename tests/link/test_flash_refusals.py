"""What `host flash` refuses before it touches a board, and what it checks after: broken
calibration files, a board file the firmware would refuse at boot, another board, a busy port,
and a read-back that does not match what it installed. Each refusal is one error line, exit 2,
and the board keeps what it had."""

import json
from pathlib import Path

import pytest

from host import cli
from host.calibration.file import encode_document, read_calibration
from host.link.board_client import BoardClient
from host.link.virtual_board import READY_CALIBRATION, VirtualBoard

from testkit.model import write_model_calibration


@pytest.fixture(scope="module")
def calibrations(tmp_path_factory):
    """{"a": (path, crc)}: a model calibration of the sim board, as test_flash.py's fixture makes it."""
    a = tmp_path_factory.mktemp("cal") / "a.json"
    return {"a": (a, write_model_calibration(a, date="2026-01-01"))}


def _bad_calibrations(d, good):
    """Files flash must refuse: each broken the way a person or a disk breaks them."""
    text = Path(good).read_text()
    crc = json.loads(text)["crc32"]
    body = read_calibration(good)
    out = {
        "empty": "",
        "truncated": text[: len(text) // 2],
        "bad CRC": text.replace('"crc32": %d' % crc, '"crc32": %d' % (crc ^ 1), 1),
        "deeply nested": "[" * 100000 + "]" * 100000,
    }
    seg = dict(body, pot1={"kind": "pwl", "fixed": [2, 4, 0, 65536, 0, 60000]})  # one 60 mm segment: dx*dy > 2**30
    out["overflowing segment"] = encode_document(seg, check=False)
    out["another board"] = encode_document(dict(body, board="pico"))
    # what only the boot's scan of every code finds: pot 2's table reversed, falling as the code rises
    n = body["pot2"]["fixed"][0]
    k = body["pot2"]["fixed"]
    out["falling curve"] = encode_document(dict(body, pot2=dict(body["pot2"], fixed=k[:2 + n] + k[2 + n:][::-1])))
    # both tables exported for a 10-bit ADC (input shift 6) onto the sim board's 12 bits
    out["another ADC width"] = encode_document(dict(body, **{p: dict(body[p], fixed=[body[p]["fixed"][0], 6] + body[p]["fixed"][2:])
                                                             for p in ("pot1", "pot2")}))
    # readable fields that contradict the tables the board would run (host/calibration/consistency.py)
    out["no board"] = encode_document(dict(body, board=None))
    out["pots naming a missing section"] = encode_document(dict(body, pots={"pot1": "a", "pot3": "c"}))
    out["readable ADC width"] = encode_document(dict(body, pot1=dict(body["pot1"], adc_bits=10)))
    worded = read_calibration(READY_CALIBRATION)  # a guided calibration: its pots carry their knots in mm
    knots = dict(worded["pot1"]["coefficients"])
    for name, change in (("knots reversed", lambda k: dict(k, knots_y=k["knots_y"][::-1])),
                         ("knots 1e300", lambda k: dict(k, knots_y=[1e300] * len(k["knots_y"]))),
                         ("3 knots", lambda k: dict(k, knots_x=k["knots_x"][:3], knots_y=k["knots_y"][:3]))):
        out[name] = encode_document(dict(worded, pot1=dict(worded["pot1"], coefficients=change(knots))))
    paths = {}
    for name, content in out.items():
        p = d / (name.replace(" ", "_") + ".json")
        p.write_text(content)
        paths[name] = p
    return paths


def test_flash_refuses_bad_files_and_another_board_before_touching_the_board(calibrations, tmp_path, capsys):
    """Each bad calibration, and --board pico onto the sim board: one error line, exit 2, and the
    board keeps the calibration it had (same CRC, same file bytes)."""
    from host import cli

    good, crc = calibrations["a"]
    with VirtualBoard(calibration=str(good)) as board:
        installed = (board.root / "calibration.json").read_bytes()
        for name, path in _bad_calibrations(tmp_path, good).items():
            code = cli.main(["flash", "--port", board.path, "--calibration", str(path)])
            err = capsys.readouterr().err.strip().splitlines()
            assert code == 2 and len(err) == 1 and err[0].startswith("error: "), (name, err)
            assert "flashed" not in err[0], (name, err)  # refused before, not found out after
            assert (board.root / "calibration.json").read_bytes() == installed, name
        code = cli.main(["flash", "--port", board.path, "--board", "pico"])
        err = capsys.readouterr().err.strip().splitlines()
        assert code == 2 and "runs lsea-kit for board sim, not pico" in err[-1], err
        with BoardClient(board.path) as client:
            assert client.status_info["calibration_crc"] == crc
        # the user says otherwise: --force installs one whose only fault is its words
        assert cli.main(["flash", "--port", board.path, "--calibration", str(tmp_path / "no_board.json"), "--force"]) == 0
        capsys.readouterr()


def test_flash_refuses_a_board_file_the_firmware_would_refuse_at_boot(calibrations, tmp_path, capsys):
    """The board file goes through the firmware's own check (board_config.load_board, what the App
    runs at boot) before the board is touched: one error line with the firmware's reason."""
    from firmware.board_config import BoardError, load_board

    board = json.loads((Path(__file__).resolve().parents[2] / "boards" / "sim.json").read_text())
    board["loop_hz"] = 1500  # not a whole number of microseconds per step
    bad = tmp_path / "sim.json"
    bad.write_text(json.dumps(board))
    with pytest.raises(BoardError) as at_boot:
        load_board(str(bad))
    with VirtualBoard(calibration=str(calibrations["a"][0])) as vb:
        installed = (vb.root / "board.json").read_bytes()
        code = cli.main(["flash", "--port", vb.path, "--board", str(bad)])
        err = capsys.readouterr().err.strip().splitlines()
        assert code == 2 and len(err) == 1 and str(at_boot.value) in err[0], err
        assert (vb.root / "board.json").read_bytes() == installed and not (vb.root / "_new").exists()


def test_flash_reads_back_every_file_it_installed(calibrations, monkeypatch, tmp_path):
    """The CRCs the board reports after the swap are compared with the files: a board that
    holds something else (here: mpremote's read-back reports other CRCs) fails the flash."""
    import host.link.flashing as flashing

    calls = []

    def fake_mpremote(port, *commands, timeout=120):
        calls.append(commands)
        code = " ".join(" ".join(c) for c in commands)
        if "swapped" in code or "os.rename" in code:
            return "swapped\n"
        if "crc32" in code:
            return "board.json 1\ncalibration.json 2\n"
        return ""

    monkeypatch.setattr(flashing, "mpremote", fake_mpremote)
    port = tmp_path / "ttyFAKE"
    port.write_text("")
    with pytest.raises(flashing.UserError) as info:
        flashing.flash(str(port), "sim", str(calibrations["a"][0]), progress=lambda s: None, ask_board=False)
    assert "verification failed" in str(info.value)
    assert any("crc32" in " ".join(" ".join(c) for c in cmds) for cmds in calls)


def test_flash_onto_a_busy_port_says_it_is_busy(calibrations, capsys):
    """Another program holding the port: one line naming that, not "no lsea-kit firmware"."""
    import serial

    with VirtualBoard(calibration=str(calibrations["a"][0])) as board:
        with serial.Serial(board.path, exclusive=True):
            code = cli.main(["flash", "--port", board.path])
        err = capsys.readouterr().err.strip().splitlines()
        assert code == 2 and len(err) == 1 and "busy" in err[0], err
