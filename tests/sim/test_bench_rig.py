"""The simulated bench rig: rig.json changes what the world measures, on CPython and MicroPython."""

import json

from boards.sim import bench_rig
from boards.sim import machine
from testkit.interpreters import REPO, run_micropython

BOARD = json.loads((REPO / "boards" / "sim.json").read_text())


def test_rig_file_mounts_the_reference_and_hooks_the_gauge(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    world = machine.configure(BOARD, seed=3)
    bench_rig.poll(world)  # no rig.json: the board file's defaults stay
    assert world.reference_on == "pot2" and world.load_kind == "none"
    (tmp_path / "rig.json").write_text(json.dumps({"reference": "pot1", "load": {"kind": "gauge", "anchor_mm": 31.0}}))
    bench_rig._last_poll = None  # do not wait the 100 ms poll interval in a test
    bench_rig.poll(world)
    assert world.reference_on == "pot1"
    assert world.load_kind == "gauge" and world.anchor_mm == 31.0
    # block at 30 mm, fibre anchored at 31: taut, 20 N/mm * 1 mm; the display shows it
    shown = json.loads((tmp_path / "gauge.json").read_text())["force_n"]
    assert abs(shown - world.gauge_reading_n) < 0.1 and abs(shown - 20.0) < 0.3


def test_poll_is_rate_limited_and_applies_only_changes(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    world = machine.configure(BOARD, seed=3)
    (tmp_path / "rig.json").write_text(json.dumps({"reference": "pot1"}))
    bench_rig.poll(world)
    assert world.reference_on == "pot1"
    world.set_reference("pot2")  # unchanged file: not applied again
    bench_rig._last_poll = None
    bench_rig.poll(world)
    assert world.reference_on == "pot2"
    (tmp_path / "rig.json").write_text(json.dumps({"reference": "pot1", "fault": {"channel": "pot1"}}))
    bench_rig.poll(world)  # within 100 ms of the last poll: not read yet
    assert world.reference_on == "pot2"
    bench_rig._last_poll = None
    bench_rig.poll(world)
    assert world.reference_on == "pot1"
    assert world.adc_code("pot1") == (1 << BOARD["adc_bits"]) - 1  # wiper lifted: reads the rail


def test_machine_idle_polls_the_rig(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    world = machine.configure(BOARD, seed=3)
    (tmp_path / "rig.json").write_text(json.dumps({"reference": "pot1"}))
    machine.idle()  # no timer yet: still polls the rig
    assert world.reference_on == "pot1"


def test_rig_runs_under_micropython(tmp_path):
    (tmp_path / "rig.json").write_text(json.dumps({"reference": "pot1", "load": {"kind": "gauge", "anchor_mm": 31.0}}))
    source = """
import json, os
from boards.sim import machine
os.chdir(%r)
board = json.loads(open(%r).read())
w = machine.configure(board, 3)
machine.idle()
print(w.reference_on, w.load_kind, json.loads(open('gauge.json').read())["force_n"] > 19.5)
""" % (str(tmp_path), str(REPO / "boards" / "sim.json"))
    out = run_micropython(source).stdout.split()
    assert out == ["pot1", "gauge", "True"]


def test_waiting_for_a_fresh_gauge_display_keeps_heartbeating(tmp_path):
    """The motor may push against the gauge while the host waits for the display: the wait
    must keep the firmware's host watchdog fed (it stops the motor after 1 s of silence)."""
    import json
    import os

    from host.guided.prompts import Prompter
    from host.guided.rig import Rig

    display = tmp_path / "gauge.json"
    display.write_text(json.dumps({"force_n": 1.0, "t_s": 0.0}))
    os.utime(display, (0, 0))  # stale: written long ago
    beats = []

    def beat():
        beats.append(1)
        if len(beats) == 3:  # the rig refreshes the display after a few polls
            display.write_text(json.dumps({"force_n": 2.5, "t_s": 1.0}))

    from host.link.virtual_board import VirtualBoard

    rig = Rig(Prompter(yes=True, out=lambda s: None), VirtualBoard(root=tmp_path))
    assert rig.gauge_reading_n(beat=beat) == 2.5
    assert len(beats) == 3  # one before each look at the display: two stale, then the fresh one
