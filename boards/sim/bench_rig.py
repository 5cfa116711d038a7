"""The bench rig around the simulated actuator: what a person mounts, read from `rig.json`.

On a real bench a person mounts the reference sensor on pot 1 or pot 2 and hooks or unhooks the
force gauge; the firmware's protocol knows nothing of it. On the virtual board the host writes the
same facts to `rig.json` in the board's filesystem root (the current directory of the firmware)
and `poll(world)`, called from `machine.idle()` outside the control step, applies them:

    {"reference": "pot1" | "pot2",
     "load": {"kind": "none" | "gauge" | "constant", "anchor_mm": 45.0, "side": "high" | "low",
              "gap_mm": 1.5, "force_n": 0.0},
     "fault": null | {"channel": "pot1", "kind": "wiper_lift", "rail": "high"}}

(load: anchor_mm where the gauge's fibre goes taut, default the board file's, and the gauge's
side, see Actuator.set_load; or, with gap_mm, the fibre hooked as a person hooks it, slack by
gap_mm from where the block is when it is hooked (the person sees the block, not its true
position: the anchor follows from the block's place, not from a number in mm); force_n of a
constant load, + toward the 60 mm end. `host sim --load` and `--port sim --load` write it too.
A load is applied when it changes, not when another part of the rig does.)

While the gauge is hooked, the rig also plays the gauge's display: `gauge.json` holds its reading
in newtons (from the gauge's own ADC channel: noise, quantisation and zero drift included) and the
simulated time, rewritten at each poll, so the host reads it as a person reads the gauge.
Polls run at most every POLL_MS of wall time and apply the file only when it changed: os.stat
first (is it there, mtime/size), then its text against the last applied text, because MicroPython's
mtime has one-second resolution and two rigs can have the same size.
"""

import json
import os
import time

POLL_MS = 100
RIG_FILE = "rig.json"
GAUGE_FILE = "gauge.json"
GAUGE_READS = 16  # a gauge display averages; so does this one

_last_poll = None
_last_text = None
_last_world = None
_gauge_on = False
_last_load = None  # the load last applied, as text

try:
    _ms = time.ticks_ms
    _ms_diff = time.ticks_diff
except AttributeError:  # CPython

    def _ms():
        return int(time.monotonic() * 1000)

    def _ms_diff(a, b):
        return a - b


def reset():
    """Forget what was applied (a new world was built)."""
    global _last_poll, _last_text, _gauge_on, _last_load
    _last_poll = None
    _last_text = None
    _gauge_on = False
    _last_load = None
_last_load = None  # the load last applied, as text


def apply(world, rig):
    """Apply one rig description (a dict like rig.json) to the Actuator `world`."""
    global _gauge_on, _last_load
    ref = rig.get("reference")
    if ref:
        world.set_reference(ref)
    load = rig.get("load")
    key = None if load is None else json.dumps(load)
    if load is not None and key != _last_load:
        _last_load = key
        kind = load.get("kind", "none")
        side = load.get("side", "high")
        anchor = load.get("anchor_mm")
        if kind == "gauge" and load.get("gap_mm") is not None:
            gap = float(load["gap_mm"])  # high side: taut below the anchor, so it sits gap below the block
            anchor = world.block_mm - gap if side == "high" else world.block_mm + gap
        world.set_load(kind, anchor_mm=anchor, side=side, force_n=float(load.get("force_n", 0.0)))
        _gauge_on = kind == "gauge"
    if "fault" in rig:
        world.clear_faults()
        fault = rig["fault"]
        if fault:
            world.inject_fault(fault["channel"], fault.get("kind", "wiper_lift"), fault.get("rail"))


def gauge_reading_n(world):
    """What the gauge shows, in N, from its ADC channel (averaged, 0.01 N display)."""
    g = world.gauge
    s = 0
    i = 0
    while i < GAUGE_READS:
        s += world.adc_code("gauge")
        i += 1
    fraction = s / GAUGE_READS / world.full_code
    return round((fraction - float(g["zero_fraction"])) * float(g["n_per_fraction"]), 2)


def _write_gauge(world):
    text = json.dumps({"force_n": gauge_reading_n(world), "t_s": world.time_s})
    with open(GAUGE_FILE + ".tmp", "w") as f:
        f.write(text)
    os.rename(GAUGE_FILE + ".tmp", GAUGE_FILE)


def poll(world):
    """Apply rig.json if it changed (at most every POLL_MS); refresh the gauge display."""
    global _last_poll, _last_text, _last_world
    if world is None:
        return
    now = _ms()
    if world is not _last_world:  # a new world starts from the board file's rig
        reset()
        _last_world = world
    elif _last_poll is not None and _ms_diff(now, _last_poll) < POLL_MS:
        return
    _last_poll = now
    try:
        os.stat(RIG_FILE)
        with open(RIG_FILE) as f:
            text = f.read()
    except OSError:
        text = None
    if text and text != _last_text:
        try:
            apply(world, json.loads(text))
            _last_text = text
        except (ValueError, KeyError, TypeError):
            pass  # half-written or wrong: try again at the next poll
    if _gauge_on:
        try:
            _write_gauge(world)
        except OSError:
            pass
