"""Where the measured spring deformation is wrong, and why: along a stretch of the stroke, on a simulated actuator.

Force control reads the spring's deformation as d = D1* - D2, two pot readings through their
calibrations; at 17 N/mm a 6 um error in d is 0.1 N, the whole 2 % of a 5 N step. This bench
shows how large that error is where the force steps run, and which pot calibration makes it.

What it runs:
1. Deformation at rest: the real firmware App on the simulated actuator (board file, no load),
   CPython, run_ticks, no real time. The block is driven to each position target (position
   mode), the motor switched off, and the firmware's deformation averaged over 400 steps against
   the simulation's true nut - block. With no load and the motor off, the spring is at rest.
2. Pot calibration error against the simulated pot: each pot's calibrated curve (the integer
   form the firmware runs, linear between codes) at the noise-free code the simulated pot gives
   at each position, minus the position; a quadratic over the stretch is removed (a frame
   shift and scale, which Df and the end-stop frame absorb), so what is left is the local error
   no smooth correction removes.

Call (from the repository root, the venv's python):
    python bench/bench_deformation_error.py --board BOARD --calibration CAL [--from MM --to MM --step MM]
BOARD a simulated board file (boards/sim.json, or a robustness run's out/robH/board-1001.json),
CAL a calibration made on it (e.g. out/robH/run-1001/calibration.json). Positions are the
firmware's D2 targets; part 2 takes the block's true positions part 1 reached (they differ by
the end-stop frame's shift, about a millimetre).

What it prints: part 1 one row per position (measured - true d, D1* - nut, D2 - block, um), part
2 one row per pot (the local error at each step), and a summary line for each.
"""

import argparse
import json
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

SETTLE_STEPS, REST_STEPS, AVERAGE_STEPS = 800, 100, 400


def deformation_at_rest(board, calibration, targets_um):
    """Rows (target um, block um, measured - true d, D1* - nut, D2 - block), um, the block free."""
    import boards.sim.machine as sim
    from firmware.app import App
    from firmware.calibration import load_calibration
    from firmware.measurement import D1, D2, DEFL
    from tests.sim.firmware_cases import _run, for_board

    app = App(board, None, machine=for_board(board))
    app.set_calibration(load_calibration(calibration))
    app.start()
    world = sim.world()
    rows = []
    try:
        for target in targets_um:
            app.set_mode("position")
            app.set_target(target)
            _run(app, SETTLE_STEPS)
            app.set_mode("idle")
            _run(app, REST_STEPS)
            gap = e1 = e2 = 0.0
            for _ in range(AVERAGE_STEPS):
                sim.run_ticks(1)
                app.heartbeat()
                st = app.ctrl.meas.st
                gap += st[DEFL] - world.deformation_mm * 1000.0
                e1 += st[D1] - world.nut_mm * 1000.0
                e2 += st[D2] - world.block_mm * 1000.0
            n = float(AVERAGE_STEPS)
            rows.append((target, world.block_mm * 1000.0, gap / n, e1 / n, e2 / n))
    finally:
        app.shutdown()
    return rows


def pot_local_error(board, calibration, positions_mm):
    """{pot: local error um at each position} of the calibration against the simulated pot."""
    import numpy as np

    from boards.sim.potentiometer import Potentiometer
    from firmware.calibration import convert
    from host.calibration.file import read_calibration

    spec = json.load(open(board))
    full = (1 << int(spec.get("adc_bits", 12))) - 1
    doc = read_calibration(calibration)
    xs = np.asarray(positions_mm, dtype=float)
    out = {}
    for pot in ("pot1", "pot2"):
        sim_pot = Potentiometer(spec["actuator"]["pots"][pot])
        section = doc[pot]

        def at(code, section=section):
            return convert(section["kind"], int(code), section["fixed"])

        um = []
        for x in xs:
            c = sim_pot.fraction(x) * full
            lo = int(np.floor(c))
            um.append(at(lo) + (c - lo) * (at(lo + 1) - at(lo)))
        err = np.asarray(um) - 1000.0 * xs
        out[pot] = err - np.polyval(np.polyfit(xs, err, 2), xs)
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--board", required=True, help="simulated board file")
    ap.add_argument("--calibration", required=True, help="calibration file made on it")
    ap.add_argument("--from", dest="lo", type=float, default=44.0, help="first position, mm (default 44)")
    ap.add_argument("--to", dest="hi", type=float, default=48.0, help="last position, mm (default 48)")
    ap.add_argument("--step", type=float, default=0.25, help="mm between positions (default 0.25)")
    a = ap.parse_args()
    for path in (a.board, a.calibration):
        if not os.path.exists(path):
            sys.exit("error: no such file: %s" % path)
    if not (a.step > 0 and a.hi >= a.lo):
        sys.exit("error: need --to >= --from and --step > 0")
    n = int(round((a.hi - a.lo) / a.step)) + 1
    positions = [a.lo + i * a.step for i in range(n)]

    print("1. deformation at rest, block free (firmware on the simulated actuator, %d-step means)" % AVERAGE_STEPS)
    print("target_um  block_um  meas-true_d  D1*-nut  D2-block")
    rows = deformation_at_rest(a.board, a.calibration, [round(p * 1000) for p in positions])
    for r in rows:
        print("%9d  %8.0f  %+11.1f  %+7.1f  %+8.1f" % r)
    gaps = [r[2] for r in rows]
    print("measured - true deformation: %+.1f .. %+.1f um over %.2f mm of stroke" % (min(gaps), max(gaps), a.hi - a.lo))

    print()
    if len(rows) < 4:
        print("2. (pot calibration error: needs at least 4 positions)")
        return
    print("2. pot calibration error against the simulated pot at those block positions, a quadratic removed (um)")
    for pot, err in pot_local_error(a.board, a.calibration, [r[1] / 1000.0 for r in rows]).items():
        print("%s  %s" % (pot, " ".join("%+.0f" % e for e in err)))
        print("%s  local error %+.1f .. %+.1f um" % (pot, min(err), max(err)))


if __name__ == "__main__":
    main()
