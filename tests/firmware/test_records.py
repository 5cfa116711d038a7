"""The records the firmware keeps across boots (firmware/records.py): a file on MicroPython, a slot
of microcontroller.nvm on CircuitPython (hal.record picks), on CPython and the MicroPython unix
port; the saved parameters and the exit cause through an nvm slot. On the emulated CircuitPython
Pico: tests/link/test_emulated_circuitpython.py."""

import sys
import types

import pytest

from firmware import hal, saved_params
from firmware.protocol import PARAMS
from firmware.records import FileRecord, NvmRecord
from testkit.interpreters import run_micropython

DEFAULTS = [row[1] for row in PARAMS]


class FlakyNvm(bytearray):
    """An nvm whose writes store every '9' as '8' (a failing flash)."""

    def __setitem__(self, key, value):
        if isinstance(key, slice):
            value = bytes(value).replace(b"9", b"8")
        super().__setitem__(key, value)


def test_an_nvm_slot_gives_back_what_was_written_and_nothing_when_erased():
    nvm = bytearray(b"\xff" * 4096)
    a, b = NvmRecord(nvm, 0, 512, "nvm:a"), NvmRecord(nvm, 512, 2048, "nvm:b")
    assert a.read(200) is None and b.read(4096) is None
    a.write("interrupted: KeyboardInterrupt")
    b.write("x" * 2040)
    assert a.read(200) == "interrupted: KeyboardInterrupt" and b.read(4096) == "x" * 2040
    a.write("quit")  # a shorter text replaces a longer one whole
    assert a.read(200) == "quit" and a.read(2) == "qu"
    assert nvm[2048 + 512:] == b"\xff" * (4096 - 2560)  # nothing written outside the slots
    with pytest.raises(ValueError, match="holds at most 2040 bytes"):
        b.write("x" * 2041)
    assert b.read(4096) == "x" * 2040


def test_a_damaged_slot_is_refused_not_half_used():
    nvm = bytearray(b"\xff" * 512)
    rec = NvmRecord(nvm, 0, 512, "nvm:params.txt")
    saved_params.save(rec, PARAMS, DEFAULTS)
    nvm[20] ^= 0x01  # one bit of the text
    with pytest.raises(ValueError, match="bad CRC"):
        rec.read(4096)
    got, why = saved_params.load(rec, PARAMS)
    assert got == {} and "nvm:params.txt unusable" in why and "CRC" in why
    nvm[0:4] = b"\x00\x00\x00\x00"  # no record's header
    assert "holds no record" in saved_params.load(rec, PARAMS)[1]
    nvm[0:2] = b"LR"
    nvm[2:4] = b"\xff\x7f"  # a length past the slot
    assert "damaged (length" in saved_params.load(rec, PARAMS)[1]


def test_a_write_the_nvm_does_not_keep_is_refused():
    rec = NvmRecord(FlakyNvm(b"\xff" * 1024), 0, 1024, "nvm:params.txt")
    values = list(DEFAULTS)
    values[0] = 900
    with pytest.raises(ValueError, match="did not read back"):
        saved_params.save(rec, PARAMS, values)


def test_hal_record_is_the_file_on_micropython_and_an_nvm_slot_on_circuitpython(tmp_path, monkeypatch):
    path = str(tmp_path / "params.txt")
    assert isinstance(hal.record(path), FileRecord) and hal.record(None) is None
    nvm = bytearray(b"\xff" * 4096)
    monkeypatch.setitem(sys.modules, "microcontroller", types.SimpleNamespace(nvm=nvm))
    params, exit_ = hal.record("params.txt"), hal.record("last_exit.txt")
    assert isinstance(params, NvmRecord) and params.name == "nvm:params.txt"
    slots = sorted((r.offset, r.offset + r.room + 8) for r in (params, exit_))
    assert slots[0][1] <= slots[1][0] and slots[1][1] <= len(nvm)  # apart, inside the 4 KiB
    values = list(DEFAULTS)
    values[1] = 20
    saved_params.save(params, PARAMS, values)
    exit_.write("quit after 5 steps, motor off")
    assert saved_params.load(hal.record("params.txt"), PARAMS) == (dict(enumerate(values)), None)
    assert hal.record("last_exit.txt").read(200) == "quit after 5 steps, motor off"


def test_the_app_keeps_its_parameters_and_exit_cause_in_nvm(monkeypatch):
    """An App on a CircuitPython-like runtime: `save`, then a new App (the next boot) loads the
    saved value and reads the exit cause the first one recorded."""
    from testkit.replay import ReplayMachine
    from firmware.app import App

    nvm = bytearray(b"\xff" * 4096)
    monkeypatch.setitem(sys.modules, "microcontroller", types.SimpleNamespace(nvm=nvm))

    def boot():
        return App("boards/sim.json", None, machine=ReplayMachine(dict((pin, [30000]) for pin in ("pot1", "pot2", "reference", "gauge"))), exit_record=hal.record("last_exit.txt"),
                   params_record=hal.record("params.txt"))

    app = boot()
    app.set_param("slew", 300)
    assert app.save_params() == {"file": "nvm:params.txt", "saved": {"slew": 300}}
    app._record_exit("interrupted: KeyboardInterrupt")
    again = boot()
    assert again.get_param("slew") == 300 and again.status()["params_saved"] == {"slew": 300}
    assert again.last_exit.startswith("interrupted: KeyboardInterrupt")


def test_the_unix_port_reads_an_nvm_slot_cpython_wrote_and_the_other_way(tmp_path):
    image = tmp_path / "nvm.bin"
    nvm = bytearray(b"\xff" * 4096)
    NvmRecord(nvm, 512, 2048, "nvm:params.txt").write("written by CPython")
    image.write_bytes(nvm)
    out = run_micropython(
        "from firmware.records import NvmRecord\n"
        "nvm = bytearray(open(%r, 'rb').read())\n"
        "print(NvmRecord(nvm, 512, 2048, 'p').read(100))\n"
        "NvmRecord(nvm, 0, 512, 'e').write('written by MicroPython')\n"
        "open(%r, 'wb').write(nvm)\n" % (str(image), str(image))).stdout
    assert out.strip() == "written by CPython"
    assert NvmRecord(bytearray(image.read_bytes()), 0, 512, "e").read(100) == "written by MicroPython"
