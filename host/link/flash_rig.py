"""The host's side of the virtual board's bench rig: `rig.json` and `gauge.json` in its flash.

On a real bench a person mounts the reference sensor, hooks the force gauge and reads its display.
On the unix-port virtual board (host/link/virtual_board.py) the host writes the same facts to
`rig.json` in the board's flash directory and reads the gauge's display from `gauge.json` there;
boards/sim/bench_rig.py, polled from the firmware's main loop, applies the one and rewrites the
other. This module is the only writer of rig.json and the only reader of gauge.json on the host.
(The emulated Pico has no such files: its node applies the rig itself, host/link/emulated_pico.)
"""

import json
import os
import time
from pathlib import Path

from host.errors import UserError

RIG_APPLY_S = 0.35  # the firmware's rig polls rig.json every 100 ms: a few polls before trusting it


class FlashRig:
    """The bench rig of a board whose flash is the directory `root`."""

    def __init__(self, root):
        self.root = Path(root)

    def mount(self, rig, wait=True):
        """Mount what `rig` says (bench_rig.apply's dict: reference, load, fault), keeping the other
        entries of rig.json; rewritten atomically, applied by the firmware's rig within ~100 ms
        (`wait`: return after a few of its polls)."""
        rig_path = self.root / "rig.json"
        try:
            state = json.loads(rig_path.read_text())
        except (OSError, ValueError):
            state = {}
        state.update(rig)
        tmp = self.root / "rig.json.tmp"
        tmp.write_text(json.dumps(state))
        os.replace(tmp, rig_path)
        if wait:
            time.sleep(RIG_APPLY_S)
        return state

    def gauge(self, beat=None, timeout_s=10.0):
        """The force gauge's display, {"force_n", "t_s"}, as the rig rewrites it after this call
        began: the host reads the gauge once the telemetry says a hold is over, and a display from
        before (the rig rewrites it every ~100 ms of its main loop, later on a busy computer) may
        show the force on its way there. `beat` (e.g. client.heartbeat_if_due) is called while
        waiting: the motor may be running meanwhile, and the firmware stops it after 1 s without
        the host."""
        path = self.root / "gauge.json"
        asked_ns = time.time_ns()
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if beat is not None:
                beat()
            try:
                if path.stat().st_mtime_ns > asked_ns:
                    return json.loads(path.read_text())
            except (OSError, ValueError, KeyError):
                pass
            time.sleep(0.02)
        raise UserError("the virtual rig shows no gauge reading (is the gauge hooked?)")
