"""The App's cases (tests/firmware/app_cases.py), each run under CPython and MicroPython: every
module imports, the step allocates nothing under heap_lock, the telemetry ring, the board files,
and what the App does with the calibration it finds; also the main loop's rest between passes
(CPython) and board_main's recovery of a calibration an interrupted install left aside
(MicroPython). The safety rules are in test_app_safety.py, the drive path in test_drive.py, the
parameters in test_params_on_both.py; the replay data (data_path, bcm3_data_path) is made in
tests/firmware/conftest.py."""

import pytest

from testkit.interpreters import REPO, run_micropython
from tests.firmware import app_cases
from tests.firmware.on_both import runner

CASES = "tests.firmware.app_cases"
both = runner(CASES)


def test_every_module_imports_on_both():
    here, there = both("case_imports()")
    assert here["modules"] == there["modules"] == list(app_cases.MODULES)
    every = sorted(p.stem for p in (REPO / "firmware").glob("*.py") if p.stem != "__init__" and p.stem not in app_cases.RUNTIME_ONLY)
    assert sorted(app_cases.MODULES) == every  # a new module joins the list or fails here


@pytest.mark.parametrize("pots", ["pwl", "bcm3"])
@pytest.mark.parametrize(
    "mode,target", [("idle", 0), ("open_loop", 2500), ("position", 20000), ("force", 3000)]
)
def test_step_allocates_nothing_under_heap_lock(request, pots, mode, target):
    path = request.getfixturevalue("data_path" if pots == "pwl" else "bcm3_data_path")
    here, there = both("case_heap_lock(PATH, %r, %d)" % (mode, target), path)
    assert there["locked"] is True  # the real interpreter really locked the heap
    assert there["before"] == there["after"], there
    assert here["duty"] == there["duty"]  # same integers on both interpreters
    if mode in ("position", "force"):  # the step really converted through this kind of pot
        assert here["pots"] == there["pots"] == [pots, pots]


def test_closed_loop_refused_without_calibration(data_path):
    here, there = both("case_refused_without_calibration(PATH)", data_path)
    assert here == there


def test_load_force_is_a_play_operator_of_the_block_friction(data_path):
    here, there = both("case_load_force_play(PATH)", data_path)
    assert here == there


def test_telemetry_ring():
    here, there = both("case_ring()")
    assert here == there


def test_board_files_load_and_broken_ones_are_explained():
    here, there = both("case_board_files()")
    assert here == there and here["boards"] == ["pico", "esp32_devkitc", "pyboard", "sim"]


def test_the_board_boots_whatever_calibration_file_it_finds(tmp_path):
    """Empty, truncated, not JSON, deeply nested (200 KB and 60 KB of '['), huge, binary: the App boots
    with no calibration on both interpreters and says why (a board that cannot boot cannot be
    repaired from the host)."""
    import json as _json

    good = _json.dumps({"format": "lsea-kit calibration", "schema": 1, "crc32": 0, "payload": "{}"})
    files = {
        "empty.json": b"",
        "truncated.json": good[: len(good) // 2].encode(),
        "text.json": b"hello",
        "nested.json": b"[" * 200000 + b"]" * 200000,  # refused by size before parsing
        "nested_small.json": b"[" * 30000 + b"]" * 30000,  # under the size limit: the parser's recursion
        "huge.json": b'{"format": "' + b"x" * 2000000 + b'"}',
        "binary.json": bytes(range(256)) * 16,
        # a valid envelope and CRC around what the loader's checks must catch
        "nested_payload.json": schema_1(b"[" * 20000 + b"]" * 20000),
        "wrong_types.json": schema_1(_json.dumps({"schema": 1, "pot1": {"kind": "pwl", "fixed": ["2", 4.5, None]},
                                                  "pot2": [1, 2]}).encode()),
        "huge_numbers.json": schema_1(_json.dumps({"schema": 1, "pot1": {"kind": "bcm3", "fixed": [10**400] * 21},
                                                   "pot2": {"kind": "pwl", "fixed": [2**64] * 6}}).encode()),
        "missing.json": None,
        "directory.json": "dir",
    }
    paths = []
    for name, data in files.items():
        p = tmp_path / name
        if data == "dir":
            p.mkdir()
        elif data is not None:
            p.write_bytes(data)
        paths.append(str(p))
    here, there = both("case_boot_survives_any_calibration(None, %r)" % paths)
    assert len(here["why"]) == len(there["why"]) == len(files)
    for why in (here["why"][-1], there["why"][-1]):  # a directory is not a missing file
        assert "cannot read" in why and "no calibration file" not in why, why
    names = list(files)
    for name in ("nested.json", "huge.json"):  # refused by their size, before the heap is asked for them
        for why in (here["why"][names.index(name)], there["why"][names.index(name)]):
            assert "larger than 65536" in why, (name, why)


def schema_1(payload):
    """A schema 1 calibration file around `payload` (bytes), with the right CRC."""
    import binascii
    import json as _json

    text = payload.decode()
    return _json.dumps({"format": "lsea-kit calibration", "schema": 1, "crc32": binascii.crc32(payload) & 0xFFFFFFFF,
                        "payload": text}).encode()


def test_board_main_puts_back_a_calibration_an_interrupted_install_left_aside(tmp_path):
    """board_main.run recovers calibration.json from calibration.json.old before anything
    else, even when the boot then fails (here: no board file)."""
    (tmp_path / "calibration.json.old").write_text("{}")
    src = (
        "import os\nos.chdir(%r)\nfrom firmware.board_main import run\n"
        "try:\n    run('no_board.json', 'calibration.json')\nexcept Exception:\n    print('boot failed')\n"
        "print(sorted(os.listdir('.')))\n" % str(tmp_path)
    )
    out = run_micropython(src).stdout
    assert "boot failed" in out and "['calibration.json']" in out, out


def test_a_falling_pot_curve_and_another_boards_calibration_are_refused(data_path):
    here, there = both("case_calibrations_the_board_refuses(PATH)", data_path)
    assert here == there


def test_the_soft_limits_stay_off_the_calibrated_end_stops(data_path):
    here, there = both("case_stroke_limits_from_end_stops(PATH)", data_path)
    assert here == there
    assert here["none"] == [500, 59500] and here["stops_none"] is None
    assert here["low_shifted"] == [500, 57700]  # 300 um (stop_margin_um) inside the high stop
    assert here["high_shifted"] == [1300, 59500]
    assert here["param_inside"] == [2000, 59500]
    assert here["margin_open"] == [2000, 59500]
    assert here["all_open"] == [1000 - 65535, 65535] and here["forgotten"] is None  # no limit inside the stroke


def test_force_targets_beyond_the_range_the_calibration_held_are_refused(data_path):
    here, there = both("case_force_targets_within_the_range_held(PATH)", data_path)
    assert here == there
    assert here["range"] == [-12500, 14000]
    assert here["accepted"] == [-12500, 14000, 3000]  # the ends themselves are held forces
    assert all(why is not None and "-12500..14000 mN" in why for why in here["refused"]), here["refused"]
    assert here["kept"] == 3000  # a refused target leaves the last one in force
    assert here["without"] == [None, -150000]


def test_a_calibration_for_another_adc_width_is_refused_before_its_codes_are_scanned(data_path, bcm3_data_path):
    here, there = both("case_calibrations_for_another_adc_width(PATH, %r)" % bcm3_data_path, data_path)
    assert here == there


def test_a_calibration_whose_evaluation_fails_leaves_the_board_running_without_it(data_path):
    """set_calibration (which the boot calls) turns any failure of the curves into the reason in
    status, motor off: here a table cut short, which only a Calibration that skipped the loader's
    checks can hold (CPython raises IndexError on it)."""
    from testkit.replay import load, load_calibration, pwm_duties, replay_app

    data = load(data_path)
    app, _ = replay_app(data)
    cal = load_calibration(data)
    kind, k = cal.pot1
    cal.pot1 = (kind, k[: 2 + k[0]])  # the knot values are missing
    app.set_calibration(cal)
    st = app.status()
    assert st["calibration_crc"] is None and "unusable" in st["calibration_error"], st
    assert pwm_duties(app) == [0, 0]
    app.set_mode("open_loop")


def test_the_main_loop_rests_between_passes_until_input_or_its_pass_is_due(monkeypatch):
    """App.run's rest: idle() (a board's sleep until its next interrupt) until PASS_MS after the
    pass, cut short by input. A pass costs ~0.2 ms of an RP2040: run at every interrupt, the
    passes kept the emulated Pico's CPU ~70 % busy at rest (docs/emulated-pico.md)."""
    from firmware import app as app_module

    clock = [0]
    wakes = []

    def idle():  # the next interrupt comes 1 ms later (the loop timer's)
        wakes.append(clock[0])
        clock[0] += 1

    monkeypatch.setattr(app_module, "_ticks_ms", lambda: clock[0])
    app_module._rest(idle, lambda: False)
    assert len(wakes) == app_module.PASS_MS > 1  # nothing to do: the pass is due PASS_MS later
    del wakes[:]
    clock[0] = 1000
    app_module._rest(idle, lambda: clock[0] >= 1003)
    assert wakes == [1000, 1001, 1002]  # input arrived at the third wake-up: the next pass at once
    del wakes[:]
    app_module._rest(idle, None)
    assert len(wakes) == 1  # a link that cannot say (a test's): one idle() per pass, as before
