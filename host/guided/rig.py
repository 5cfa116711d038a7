"""The bench rig: what a person mounts for each step, and, on the virtual board, doing it.

On a real board the rig prints the instruction and waits for Enter. On the virtual board it also
writes `rig.json` into the board's filesystem root (atomically: temp file then rename), where
boards/sim/bench_rig.py applies it to the simulated world within ~100 ms; the gauge's display is
read back from `gauge.json` there. The reference sensor's scale (its datasheet: the position at
code 0 and the span over full scale) comes from the board file on the simulated board
("actuator.reference") and from --ref-zero-mm / --ref-span-mm on a real one.
"""

import json
import os
import time
from pathlib import Path

from host.errors import UserError

APPLY_S = 0.35  # the rig polls every 100 ms; wait a few polls before trusting the new state


class Rig:
    def __init__(self, prompter, root=None):
        self.prompter = prompter
        self.root = Path(root) if root else None
        self.state = {"reference": None, "load": {"kind": "none"}, "fault": None}

    @property
    def virtual(self):
        return self.root is not None

    def _write(self):
        tmp = self.root / "rig.json.tmp"
        tmp.write_text(json.dumps(self.state))
        os.replace(tmp, self.root / "rig.json")
        time.sleep(APPLY_S)

    def _do(self, instruction, **change):
        self.state.update(change)
        self.prompter.wait(instruction)
        if self.virtual:
            self._write()

    def mount_reference(self, pot):
        which = "1 (nut, D1)" if pot == "pot1" else "2 (output block, D2)"
        self._do("Mount the reference sensor in parallel with potentiometer %s; unhook the force gauge." % which,
                 reference=pot, load={"kind": "none"})

    def no_load(self):
        self._do("Unhook the force gauge: the output block must run free end to end (no load).", load={"kind": "none"})

    def hook_gauge(self, anchor_mm, side="high"):
        """side "high": the gauge sits toward 60 mm and the block pulls it toward 0 mm (negative
        actuator forces, the paper's rig); "low": toward 0 mm, the block pushes away from it."""
        where = ("on the 60 mm side (the block pulls it toward 0 mm)" if side == "high"
                 else "on the 0 mm side (the block pulls it toward 60 mm)")
        self._do("Hook the force gauge to the output block through the fibre, %s, anchored so it goes "
                 "taut at D2 = %.0f mm." % (where, anchor_mm),
                 load={"kind": "gauge", "anchor_mm": float(anchor_mm), "side": side})

    def set_fault(self, fault):
        """Simulated boards only (tests): make a channel misbehave, e.g. {"channel": "pot1"}."""
        if not self.virtual:
            raise UserError("faults can only be injected on the virtual board")
        self.state["fault"] = fault
        self._write()

    def gauge_reading_n(self, question="Force gauge reading (N):", max_age_s=1.0):
        """The force gauge's reading: from the virtual rig's display, else typed by the person."""
        if not self.virtual:
            return self.prompter.number(question)
        path = self.root / "gauge.json"
        deadline = time.monotonic() + 3.0
        while time.monotonic() < deadline:
            try:
                if time.time() - path.stat().st_mtime <= max_age_s:
                    return float(json.loads(path.read_text())["force_n"])
            except (OSError, ValueError, KeyError):
                pass
            time.sleep(0.05)
        raise UserError("the virtual rig shows no gauge reading (is the gauge hooked?)")


def reference_scale(board, zero_mm=None, span_mm=None):
    """(zero_mm, span_mm) of the reference sensor: options first, else the simulated board's file."""
    ref = (board.get("actuator") or {}).get("reference") or {}
    zero = zero_mm if zero_mm is not None else ref.get("zero_mm")
    span = span_mm if span_mm is not None else ref.get("span_mm")
    if zero is None or span is None:
        raise UserError("give the reference sensor's scale: --ref-zero-mm (position at code 0) and "
                        "--ref-span-mm (travel over full scale), or use --reference manual")
    return float(zero), float(span)


def reference_mm(raw_ref, adc_bits, scale):
    zero, span = scale
    return zero + span * (raw_ref.astype(float) / ((1 << adc_bits) - 1))
