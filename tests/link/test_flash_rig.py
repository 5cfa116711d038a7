"""The host's side of the virtual board's rig files (host/link/flash_rig.py), against the rig the
firmware's main loop runs (boards/sim/bench_rig.py) on a simulated world."""

import json
import os
import time

import pytest

from boards.sim import bench_rig
from boards.sim import machine
from host.errors import UserError
from host.link.flash_rig import FlashRig
from testkit.interpreters import REPO

BOARD = json.loads((REPO / "boards" / "sim.json").read_text())


def _poll(world):
    bench_rig._last_poll = None  # do not wait the 100 ms poll interval in a test
    bench_rig.poll(world)


def test_a_mount_keeps_what_was_mounted_before_and_the_firmware_applies_both(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    world = machine.configure(BOARD, seed=3)
    rig = FlashRig(tmp_path)
    rig.mount({"reference": "pot1"}, wait=False)
    state = rig.mount({"load": {"kind": "gauge", "anchor_mm": 31.0}}, wait=False)
    assert state == {"reference": "pot1", "load": {"kind": "gauge", "anchor_mm": 31.0}}
    assert not (tmp_path / "rig.json.tmp").exists()  # written aside, then moved into place
    _poll(world)
    assert world.reference_on == "pot1" and world.load_kind == "gauge" and world.anchor_mm == 31.0
    shown = json.loads((tmp_path / "gauge.json").read_text())["force_n"]  # rewritten at that poll
    assert abs(shown - world.gauge_reading_n) < 0.1


def test_the_host_reads_only_a_gauge_display_rewritten_after_it_asked(tmp_path, monkeypatch):
    # The host reads the gauge once the telemetry says a hold is over; a display the rig wrote
    # before (moments ago, while the force was on its way) must not be the answer.
    monkeypatch.chdir(tmp_path)
    world = machine.configure(BOARD, seed=3)
    rig = FlashRig(tmp_path)
    rig.mount({"load": {"kind": "gauge", "anchor_mm": 31.0}}, wait=False)
    _poll(world)
    (tmp_path / "gauge.json").write_text(json.dumps({"force_n": 123.0, "t_s": 0.0}))  # fresh, but from before
    beats = []

    def beat():  # the host's heartbeat while it waits; the rig polls meanwhile, as the firmware's loop does
        beats.append(1)
        if len(beats) == 3:
            _poll(world)

    shown = rig.gauge(beat=beat, timeout_s=5.0)
    assert len(beats) >= 3 and shown["force_n"] != 123.0
    assert abs(shown["force_n"] - world.gauge_reading_n) < 0.1


def test_a_stale_gauge_display_is_waited_for_then_refused_in_one_line(tmp_path):
    (tmp_path / "gauge.json").write_text(json.dumps({"force_n": 1.0, "t_s": 0.0}))
    old = time.time() - 5.0
    os.utime(tmp_path / "gauge.json", (old, old))
    beats = []
    with pytest.raises(UserError, match="no gauge reading"):
        FlashRig(tmp_path).gauge(beat=lambda: beats.append(1), timeout_s=0.2)
    assert beats  # the host's heartbeat kept going while it waited
