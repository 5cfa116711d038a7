"""The offline force rig the offline benches share: the actuators of a robustness run (its board
files, as the run used them) with a calibration (the run's own, re-identified by replaying the
guided force step, friction-trimmed in closed loop, exact, or with its friction replaced), where
the gauge hooks on each board, the step sequence, and the settings of one invocation (`RUN`).

Used by bench/bench_force_steps_offline.py (its docstring says what each option changes) and
bench/bench_force_error_budget.py; the cases themselves are tests/sim/force_cases.py.
"""

import json
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

TARGETS = (5000, 10000, 15000, 10000, 5000)
PRELOAD = 500


class Run:
    """What this invocation runs, set once from the options (main) and read by every case; the
    defaults are the bench's plain run. bench/bench_force_error_budget.py sets it as well."""

    targets = TARGETS  # mN magnitudes of the step sequence (--targets)
    settle = 1500  # ticks each step settles, then is measured over `hold` (1.5 s and 0.5 s at 1 kHz)
    hold = 500
    anchor_um = 45000  # the gauge anchor in force now (--anchor, --anchors: other realisations of a board)
    at_gauge = False  # --at-gauge: anchors are offsets from each board's own gauge anchor, where --trim holds too
    measured = True  # the loads the gauge shows (BenchGauge), or with --true-load the simulator's true ones
    refit = False  # --refit
    trim = False  # --trim, --no-f0, --trim-fractions
    trim_f0 = True
    trim_fractions = None
    # diagnostics: --oversample, --oversample-times, --noise, --loop-hz, --friction
    oversample = None
    oversample_times = None
    noise = None
    loop_hz = None
    friction = None

    def at_rate(self, loop_hz):
        """Every board at `loop_hz`; settle and hold keep their seconds."""
        self.loop_hz = loop_hz
        self.settle, self.hold = 1500 * loop_hz // 1000, 500 * loop_hz // 1000


RUN = Run()
SIDES = (("high", -1), ("low", 1))


def paths(runs, seed):
    """(board file, identified calibration) of a seed."""
    if seed == "sim":
        return os.path.join(ROOT, "boards", "sim.json"), os.path.join(runs, "run-base", "calibration.json")
    return os.path.join(runs, "board-%s.json" % seed), os.path.join(runs, "run-%s" % seed, "calibration.json")


def exact_calibration(board_path, out_path):
    """An exact model calibration of the board, in the firmware's own deformation (see docstring)."""
    import numpy as np

    from boards.sim.actuator import Actuator
    from host.calibration.file import force_table_section, friction_section
    from testkit import model

    board = json.load(open(board_path))
    w = Actuator(dict(board["actuator"], adc_bits=board["adc_bits"]), 1)
    m1 = w.pots[0].mount_error_mm
    m2 = w.pots[1].mount_error_mm
    lo, hi = model.stroke_of(board)
    xs = np.linspace(lo - 1.0, hi + 1.0, int(round((hi - lo + 2.0) * 100)) + 1)
    d1g = xs + np.array([m1(x) for x in xs])
    dfg = d1g - (xs + np.array([m2(x) for x in xs]))
    kg = float(board["actuator"]["gauge"]["stiffness_n_per_mm"])
    dt = np.unique(np.concatenate([np.linspace(-2.0, 2.0, 81), [-w.d_release, w.d_release]]))
    f = np.array([w.spring_force(v) for v in dt])
    # within 24 N, and no two points in the same um (a knot next to the release point's)
    keep = (np.abs(f) <= 24.0) & np.concatenate([[True], np.diff(dt) > 0.002])
    dt, f = dt[keep], f[keep]
    x2 = RUN.anchor_um / 1000.0 + f / kg
    x1 = x2 + dt
    d1 = x1 + np.array([m1(x) for x in x1])
    dm = d1 - np.interp(d1, d1g, dfg) - (x2 + np.array([m2(x) for x in x2]))
    sec_f = force_table_section(dm, f, (-2.0, 2.0), ("um", "mN"))
    sec_i = force_table_section(f, dm, (-25.0, 25.0), ("mN", "um"))
    h = float(board["actuator"]["block"]["coulomb_n"])  # in the host's form, which --trim reads and rewrites
    # pot tables with a knot every 1/8 mm: within a micrometre of the pots between knots (a knot a
    # millimetre strays up to 30 um near the knees, 0.4 N of a 13 N/mm spring)
    pots = model.model_sections(board, n_points=int(round((hi - lo) * 8)) + 1, unrounded=True)
    model.write_model_calibration(out_path, board=board, pot1=pots["pot1"], pot2=pots["pot2"], df=pots["df"],
                                  force=sec_f, force_inverse=sec_i, friction=friction_section(h))
    return out_path


_TOLD_NO_ROW = set()


def as_run(runs, seed, board, tmp):
    """The board file as the run used it: bringup's --fix may have raised `oversample` (row.json
    records the value), and 4 reads a step instead of 16 double the deformation's noise. Then
    the diagnostics' changes, if any."""
    row = os.path.join(runs, "run-base" if seed == "sim" else "run-%s" % seed, "row.json")
    oversample = json.load(open(row)).get("oversample") if os.path.exists(row) else None
    data = json.load(open(board))
    if oversample is None and RUN.oversample is None and seed not in _TOLD_NO_ROW:
        _TOLD_NO_ROW.add(seed)  # a board drawn again from its seed has no run: easy to miss
        print("%s: no %s, so the board file's %d reads a step (a run's bringup may have set more: "
              "--oversample N to match it)" % (seed, row, data.get("oversample", 4)), file=sys.stderr, flush=True)
    oversample = RUN.oversample or oversample
    if RUN.oversample_times:
        oversample = min(64, (oversample or data.get("oversample", 4)) * RUN.oversample_times)
    if (not oversample or data.get("oversample") == oversample) and RUN.noise is None and not RUN.loop_hz:
        return board
    if oversample:
        data["oversample"] = oversample
    if RUN.loop_hz:
        data["loop_hz"] = RUN.loop_hz
    if RUN.noise is not None:
        for pot in ("pot1", "pot2"):
            data["actuator"]["pots"][pot]["noise_lsb"] = RUN.noise
    out = os.path.join(tmp, "board-%s.json" % seed)
    with open(out, "w") as f:
        json.dump(data, f)
    return out


REFIT_ROUNDS = 2  # the guided step's defaults: --rounds 2, --levels 8 (625 duty), --force-range 16
REFIT_LEVEL, REFIT_MAX_DUTY, REFIT_RANGE_MN = 625, 9000, 16000
REFIT_ANCHOR = 45000  # where the run identified F0 (--anchor-mm 45); the steps may then go elsewhere


def run_ladder(runs, seed):
    """{side's sign: the loading duties} the run's force step went up through on this board (its
    force-points.csv), or {} when the run left none. A drawn motor's ladder is not 625 duty a level:
    the step shrinks on a strong motor and the top follows the force range."""
    import numpy as np

    path = os.path.join(runs, "run-%s" % seed, "force-points.csv")
    if not os.path.exists(path):
        return {}
    a = np.genfromtxt(path, delimiter=",", names=True)
    out = {}
    for sign in (-1, 1):
        on = (a["loading"] > 0) & (np.sign(a["duty"]) == sign)
        if np.any(on):
            out[sign] = sorted({int(round(abs(v))) for v in a["duty"][on]})
    return out


def refit_calibration(board, cal, out_path, anchor, ladder=None):
    """The run's calibration with its force sections identified again, here and now: the guided
    force step's open-loop points replayed on the board with the run's pots and Df
    (case_force_points_sim at `anchor`, REFIT_ROUNDS rounds a side, each on a freshly started
    firmware), fitted by the guided step's own code (host/guided/force_calibration.py identify
    and force_sections). Each side goes up the run's own ladder (`ladder`, run_ladder) when there
    is one, else in 625 duty levels until the gauge reads 16 N or the spring nears the cavity
    (boards/sim.json's). What a change to the force fit does to the force steps, without a run of
    the whole chain."""
    import numpy as np

    from host.calibration.file import read_calibration, write_calibration
    from host.guided.force_calibration import CAVITY_NEAR_MM
    from host.guided.force_identification import TAUT_N, force_sections, identify
    from tests.sim.force_cases import case_force_points_sim

    ladder = ladder or {}
    pts = []
    for side, sign in SIDES:
        levels = ladder.get(sign) or list(range(REFIT_LEVEL, REFIT_MAX_DUTY + 1, REFIT_LEVEL))
        stop_mn, stop_um = (0, 0) if sign in ladder else (REFIT_RANGE_MN, int(CAVITY_NEAR_MM * 1000))
        for _ in range(REFIT_ROUNDS):
            rows = case_force_points_sim(cal, side, levels, anchor=anchor, board_path=board, measured=RUN.measured,
                                         stop_mN=stop_mn, stop_um=stop_um)
            top = sum(1 for r in rows if r[2])
            duties = levels[:top] + levels[:top - 1][::-1]
            for (d_um, f_mn, loading), duty in zip(rows, duties):
                # s as the guided step gives it: +1 after the force fell
                pts.append((d_um / 1000.0, f_mn / 1000.0, (1 if loading else -1) * -sign, bool(loading), sign * duty))
    d, f, s, loading, duty = (np.array(c) for c in zip(*pts))
    taut = np.abs(f) > TAUT_N
    fit, drive, _ = identify(d[taut], f[taut], s[taut], loading[taut], duty[taut].astype(float))
    doc = read_calibration(cal)
    doc.update(force_sections(fit, drive))
    write_calibration(out_path, doc)
    print("      refit: %d points (%d left out inside the band), F0 %s, h %.3f N" % (
        np.count_nonzero(taut), np.count_nonzero(fit.left_out), "table" if fit.kind == "pwl" else
        "order %d" % fit.order_f, fit.friction_n), flush=True)
    return out_path


def trimmed_calibration(board, cal, out_path, anchor):
    """The calibration with its friction trimmed in closed loop as the guided step does it after
    the force step (host/guided/friction_trim.py): force-mode holds at the trim's targets for a
    16 N range on both sides, at REFIT_ANCHOR, on a freshly started firmware each side; a
    corrected F0 kept only when the check's holds (CHECK_FRACTIONS) read nearer the gauge with
    it than without it, as host/guided/flow.py decides."""
    from host.calibration.file import read_calibration, write_calibration
    from host.guided.friction_trim import (CHECK_FRACTIONS, TRIM_FRACTIONS, keep_correction, rms_error_mn,
                                           trimmed_friction, trimmed_sections)

    doc = read_calibration(cal)
    trim = trimmed_friction(doc["friction"]["friction_n"], side_holds(cal, board, RUN.trim_fractions or TRIM_FRACTIONS, anchor))
    if not RUN.trim_f0:
        trim.f0.why = "--no-f0"
    sections, lines = trimmed_sections(doc, trim)
    if "force" in sections:
        rms = {}
        for name, chosen in (("with", sections), ("without", {"friction": sections["friction"]})):
            write_calibration(out_path, dict(doc, **chosen))
            rms[name] = rms_error_mn(side_holds(out_path, board, CHECK_FRACTIONS, anchor))
        if not keep_correction(rms["with"], rms["without"]):
            sections = {"friction": sections["friction"]}
        lines.append("F0 correction %s: check rms %.0f mN with it, %.0f without" % (
            "kept" if "force" in sections else "NOT kept", rms["with"], rms["without"]))
    doc.update(sections)
    write_calibration(out_path, doc)
    for line in lines:
        print("      trim: " + line, flush=True)
    return out_path


def side_holds(cal, board, fractions, anchor):
    """Force-mode holds at `fractions` of a 16 N range on both sides, as side_holds in
    host/guided/friction_trim.py gives them: {sign: [(magnitude, estimate, gauge)]} (N)."""
    from host.guided.friction_trim import trim_magnitudes
    from tests.sim.force_cases import case_force_steps_sim

    magnitudes = trim_magnitudes(REFIT_RANGE_MN / 1000.0, fractions)
    sides = {}
    for side, sign in SIDES:
        rows = case_force_steps_sim(cal, side, [sign * round(m * 1000) for m in magnitudes], anchor=anchor,
                                    measured=RUN.measured, board_path=board)
        sides[sign] = [(m, sign * est / 1000.0, sign * load / 1000.0) for m, (_, est, load) in zip(magnitudes, rows)]
    return sides


def calibration(runs, seed, exact, tmp):
    board, cal = paths(runs, seed)
    if not os.path.exists(board):
        return board, None
    board = as_run(runs, seed, board, tmp)
    if exact:
        cal = exact_calibration(board, os.path.join(tmp, "exact-%s.json" % seed))
        if RUN.refit:  # exact pots and Df, the force sections identified by the guided step's replay
            out = os.path.join(tmp, "exact-refit-%s.json" % seed)
            cal = out if os.path.exists(out) else refit_calibration(board, cal, out, RUN.anchor_um if RUN.at_gauge else REFIT_ANCHOR)
        if RUN.trim:  # the exact F0 with h trimmed in closed loop, as the guided calibration trims its own
            out = os.path.join(tmp, "exact-trim-%s.json" % seed)
            cal = out if os.path.exists(out) else trimmed_calibration(board, cal, out, RUN.anchor_um if RUN.at_gauge else REFIT_ANCHOR)
        return board, cal
    if not os.path.exists(cal):
        return board, None
    cal = without_force_range(cal, os.path.join(tmp, "run-%s.json" % seed))
    if RUN.refit:
        out = os.path.join(tmp, "refit-%s.json" % seed)
        cal = out if os.path.exists(out) else refit_calibration(board, cal, out, RUN.anchor_um if RUN.at_gauge else REFIT_ANCHOR,
                                                                run_ladder(runs, seed))
    if RUN.trim:
        out = os.path.join(tmp, "trim-%s.json" % seed)
        cal = out if os.path.exists(out) else trimmed_calibration(board, cal, out, RUN.anchor_um if RUN.at_gauge else REFIT_ANCHOR)
    if RUN.friction:
        cal = friction_replaced(board, cal, os.path.join(tmp, "friction-%s.json" % seed), RUN.friction)
    return board, cal


def without_force_range(cal, out_path):
    """The calibration without its force_range section (a copy at `out_path` when it has one): the
    benches hold their own targets (to 15 N, the trim's to 14.4 N) whatever the run's force step
    reached, as the firmware did before it refused targets beyond that range."""
    from host.calibration.file import read_calibration, write_calibration

    doc = read_calibration(cal)
    if doc.pop("force_range", None) is None:
        return cal
    write_calibration(out_path, doc)
    return out_path


def friction_replaced(board, cal, out_path, how):
    """Diagnostic: the calibration with its friction h replaced by the board's true Coulomb friction
    ("true") or the force step's identified one before the trim ("identified")."""
    from host.calibration.file import read_calibration, write_calibration

    doc = read_calibration(cal)
    section = doc["friction"]
    h = (json.load(open(board))["actuator"]["block"]["coulomb_n"] if how == "true"
         else section["fit"]["identified_n"])
    section["friction_n"] = h
    section["fixed"] = [int(round(h * 1000))] + list(section["fixed"][1:])
    write_calibration(out_path, doc)
    return out_path


def override_params(pairs):
    """Replace firmware parameter defaults (before any App is made: the controller copies them)."""
    import firmware.protocol as protocol

    names = [row[0] for row in protocol.PARAMS]
    new = {}
    for pair in pairs:
        name, _, value = pair.partition("=")
        if name not in names or not value.lstrip("-").isdigit():
            sys.exit("--param wants NAME=INTEGER with NAME one of: %s (got %r)" % (", ".join(names), pair))
        new[name] = int(value)
    protocol.PARAMS = tuple((row[0], new[row[0]]) + tuple(row[2:]) if row[0] in new else row
                            for row in protocol.PARAMS)


def gauge_anchor_um(runs, seed):
    """Where the guided calibration hooks the gauge on this seed's board (host/guided/stroke.py)."""
    from host.guided import stroke

    board = json.load(open(paths(runs, seed)[0]))
    return round(1000 * stroke.gauge_anchor_mm(stroke.nominal(board, board.get("actuator"))))
