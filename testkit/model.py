"""Calibrations and ADC recordings of the simulated actuator (boards/sim), for tests and benchmarks.

`model_document` is a calibration of the simulated actuator made the way the paper makes it, but
from the physical model itself instead of a noisy sweep: each pot against its own wiper travel
(a pwl table, or the paper's BCM-3), Df = D1 - D2 at no load as a polynomial in D1 (order 8: a
quartic in the true position is not one in D1), F0(d) and d(F0) fitted to the model's spring
curve, and the block's Coulomb friction. It is written as a calibration file by the real
calibration-file code (host/calibration/file.py), so the firmware reads exactly what a board
reads. `write_replay_data` records ADC codes of the running actuator for the replay machine
(testkit/replay.py) and writes, beside them, the calibration files the firmware cases load.
CPython only.
"""

import json
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
DATE = "2026-01-01T00:00:00+00:00"  # model files are made, not measured: a fixed date, a fixed CRC


def sim_board():
    return json.loads((REPO / "boards" / "sim.json").read_text())


def _world(board, seed):
    from boards.sim.actuator import Actuator

    return Actuator(dict(board["actuator"], adc_bits=board["adc_bits"]), seed)


def spring_forces(board, d_mm):
    """The simulated spring pair's force (N) at deformations `d_mm`."""
    world = _world(board, 1)
    return np.array([world.spring_force(v) for v in np.asarray(d_mm, dtype=float)])


def stroke_of(board):
    """(low, high) mm: the block's stroke in the simulated actuator of `board`."""
    lo, hi = board["actuator"]["block"]["stroke_mm"]
    return float(lo), float(hi)


SPRING_ORDER = 7  # the model calibration's F0(d) and d(F0) polynomials


def model_sections(board=None, n_points=None, feed_forward=False, unrounded=False):
    """The sections pot1, pot2 (pwl tables), df, deformation_offset, deformation_gain, force, force_inverse and friction, each
    {"kind", "fixed"} as the firmware reads them; with `feed_forward` the friction section also
    holds the duty at which the stalled motor holds the spring at the friction force.

    Each pot-table knot pairs a position with its rounded noise-free code, up to half a code
    (7-10 um) off, as the firmware tests' calibration has always had it (their bounds were set
    with it). `unrounded` pairs it with the unrounded code instead: exact at the knots, which the
    offline benches' --exact needs (with a knot every 1/8 mm the rounded pairing made the
    deformation 10-20 um wrong in places, 0.1-0.25 N; docs/robustness.md, stop 43)."""
    from host.calibration.fixed_export import export_poly, export_pwl

    board = board or sim_board()
    world = _world(board, 1)
    bits = board["adc_bits"]
    lo, hi = stroke_of(board)  # 0-60 mm on boards/sim.json; drawn boards' are 40-80 mm, some below 0
    xs = np.linspace(lo, hi, n_points or int(round(hi - lo)) + 1)  # a knot a millimetre
    codes = {"pot1": [], "pot2": []}
    travel = {"pot1": [], "pot2": []}
    for x in xs:
        world.place(x)
        for i, name in enumerate(("pot1", "pot2")):
            codes[name].append(world.code_value(name) if unrounded else world.true_code(name))
            travel[name].append(x + world.pots[i].mount_error_mm(x))
    out = {}
    for name in ("pot1", "pot2"):
        c = np.asarray(codes[name], dtype=float)
        t = np.asarray(travel[name], dtype=float)
        keep = np.concatenate([[True], np.diff(c) > 0])  # the table needs increasing codes
        out[name] = {"kind": "pwl", "fixed": list(export_pwl(c[keep], t[keep], bits, max_error_um=1e9))}
    # the deformation gain: with Df out, D1* - D2 reads the true deformation times the slope of pot
    # 2's wiper travel where the block is (firmware/measurement.py), 1 + e2'(x), so g = 1 / (1 + e2'(x))
    from host.calibration.file import gain_section, offset_section

    e2 = world.pots[1].mount_error_mm
    slope = np.array([(e2(x + 0.01) - e2(x - 0.01)) / 0.02 for x in xs])
    out["deformation_gain"] = gain_section(np.asarray(travel["pot2"]), 1.0 / (1.0 + slope))
    d1 = np.asarray(travel["pot1"])
    df = d1 - np.asarray(travel["pot2"])
    df_coeffs = np.polyfit(d1, df, 8)
    out["df"] = _poly(export_poly(df_coeffs, float(d1.min()), float(d1.max()), 1000, 1000, max_error=5))
    # and what the order-8 Df leaves at no load where the block is (a few um here)
    out["deformation_offset"] = offset_section(np.asarray(travel["pot2"]), df - np.polyval(df_coeffs, d1))
    cav = float(board["actuator"]["springs"]["cavity_mm"])
    d = np.linspace(-cav, cav, 401)
    f = np.array([world.spring_force(v) for v in d])
    # order 7: the spring pair's preload lifts off inside the cavity, and a cubic over it was
    # 0.27 N too strong at 5 N (0.54 N at worst within +-1.5 mm); order 7 is within 0.07 N there
    out["force"] = _poly(export_poly(np.polyfit(d, f, SPRING_ORDER), -cav, cav, 1000, 1000))
    out["force_inverse"] = _poly(export_poly(np.polyfit(f, d, SPRING_ORDER), float(f.min()), float(f.max()), 1000, 1000))
    h = float(board["actuator"]["block"]["coulomb_n"])
    out["friction"] = {"kind": "friction", "fixed": [int(round(h * 1000))]}  # the block's Coulomb, mN
    if feed_forward:  # and the duty at which the stalled motor holds the spring at that force
        stall_n = world.eta * world.kt * world.G * float(board["supply_volts"]) / world.R  # at full duty
        out["friction"]["fixed"].append(int(round(h / (stall_n / 10000.0))))
    return out


def _poly(words):
    return {"kind": "poly", "fixed": list(words)}


def bcm3_pot_fits(board, noisy=False, seed=1):
    """{pot: FitResult}: each pot's code against its own wiper travel over the stroke (601
    places), fitted by the paper's rational cubic Bezier (host.fitting.models). `noisy` takes one
    noisy ADC read per place (seeded) instead of the noise-free code."""
    from host.fitting.models import fit_model

    world = _world(board, seed)
    xs = np.linspace(*stroke_of(board), 601)
    fits = {}
    for i, name in enumerate(("pot1", "pot2")):
        codes, travel = [], []
        for x in xs:
            world.place(x)
            codes.append(world.adc_code(name) if noisy else world.true_code(name))
            travel.append(x + world.pots[i].mount_error_mm(x))
        order = np.argsort(codes, kind="stable")
        fits[name] = fit_model("bcm", np.asarray(codes, float)[order], np.asarray(travel)[order], 3)
    return fits


def bcm3_sections(board, noisy=False, seed=1):
    """The pot sections as the paper's BCM-3 (bcm3 words from host.calibration.fixed_export)."""
    from host.calibration.fixed_export import export_bcm3

    out = {}
    for name, fit in bcm3_pot_fits(board, noisy, seed).items():
        k = export_bcm3(fit.coefficients, board["adc_bits"])
        assert k.max_error <= k.bound
        out[name] = {"kind": "bcm3", "fixed": list(k)}
    return out


def model_document(board=None, pots="pwl", date=DATE, feed_forward=False, **sections):
    """The calibration payload of the simulated actuator: pots "pwl" (tables) or "bcm3", dated
    `date` (two files of different dates differ in their CRC), then `sections` replaced (None
    removes one)."""
    from host.calibration.file import new_document

    board = board or sim_board()
    doc = new_document(board=board["name"], date=date)
    doc.update(model_sections(board, feed_forward=feed_forward))
    if pots == "bcm3":
        doc.update(bcm3_sections(board))
    for name, section in sections.items():
        if section is None:
            doc.pop(name, None)
        else:
            doc[name] = section
    return doc


def write_model_calibration(path, board=None, pots="pwl", date=DATE, feed_forward=False, **sections):
    """Write the model calibration (model_document) to `path` with the real calibration-file
    code; returns the file's CRC."""
    from host.calibration.file import write_calibration

    return write_calibration(path, model_document(board, pots, date, feed_forward, **sections))


def record_codes(board, steps, duty=3000, seed=7):
    """ADC read_u16 values of every ADC pin, recorded from the simulated actuator while the
    motor runs at `duty` (of 10000) for `steps` control periods from mid-stroke, for replay."""
    world = _world(board, seed)
    world.set_motor_voltage(board["supply_volts"] * duty / 10000.0)
    dt = 1.0 / board["loop_hz"]
    n = board["oversample"]
    out = {name: [] for name in board["adc_pins"]}
    for _ in range(steps):
        world.advance(dt)
        for name in out:
            for _ in range(n):
                out[name].append(world.adc_u16(name))
    return out


def write_replay_data(directory, steps=600, duty=3000, pots="pwl", board=None):
    """Record `steps` periods of ADC codes (record_codes) and write the calibration files the
    firmware cases boot with, into `directory`; returns the path of the data file (read by
    testkit.replay.load). Calibrations: "model" (model_document), "pots_only" (no Df, force or
    friction), "other_board" (made for the pico), "stroke_low_shifted" and "stroke_high_shifted"
    (end stops at -2/58 and 1/61 mm), "force_range" (forces held -12.5..+14 N), and for pwl pots "falling" (pot 2's table with its
    positions reversed: falls as the code rises) and "narrow" (tables for a 10-bit ADC), for
    bcm3 pots "wide" (input shift 0: a 29-bit ADC)."""
    from host.calibration.file import encode_document

    board = board or sim_board()
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    doc = model_document(board, pots)
    variants = {"model": doc,
                "pots_only": {k: v for k, v in doc.items() if k not in ("df", "force", "force_inverse", "friction")},
                "other_board": dict(doc, board="pico"),
                "stroke_low_shifted": dict(doc, stroke={"kind": "stroke", "fixed": [-2000, 58000]}),
                "stroke_high_shifted": dict(doc, stroke={"kind": "stroke", "fixed": [1000, 61000]}),
                "force_range": dict(doc, force_range={"kind": "force_range", "fixed": [-12500, 14000]})}
    if doc["pot2"]["kind"] == "pwl":
        k = doc["pot2"]["fixed"]
        n = k[0]
        variants["falling"] = dict(doc, pot2={"kind": "pwl", "fixed": k[:2 + n] + list(reversed(k[2 + n:]))})
        # input shift 6: tables for a 10-bit ADC
        variants["narrow"] = dict(doc, **{p: {"kind": "pwl", "fixed": [doc[p]["fixed"][0], 6] + doc[p]["fixed"][2:]}
                                          for p in ("pot1", "pot2")})
    else:  # input shift 0: a bcm3 that declares 29 bits
        variants["wide"] = dict(doc, **{p: {"kind": "bcm3", "fixed": [0] + doc[p]["fixed"][1:]} for p in ("pot1", "pot2")})
    paths = {}
    for name, body in variants.items():
        path = directory / ("%s-%s.json" % (pots, name))
        # the board's own refusals (falling, another ADC width) come after the file's layout checks
        path.write_text(encode_document(body, check=name not in ("falling", "narrow", "wide")))
        paths[name] = str(path)
    data = directory / ("%s-data.json" % pots)
    data.write_text(json.dumps({"codes": record_codes(board, steps, duty), "calibrations": paths}))
    return str(data)
