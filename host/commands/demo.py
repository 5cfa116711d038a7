"""`host demo`: the main job end to end on the bundled example sweep (no hardware needed).

Fits the simulated 60 mm pot sweep with the paper's BCM (degree 3) and with `--model auto`,
writes a Markdown report with the statistics, the fit figures and a calibration file the
firmware can load, and prints where they are.
"""

import sys
from pathlib import Path

from host.errors import DONE, UserError
from host.terminal import note, output


def add_parser(subparsers):
    p = subparsers.add_parser(
        "demo",
        help="fit the bundled example sweep and write a report, plots and a calibration file",
        description="Run the calibration fit end to end on the bundled example sweep (a simulated "
        "60 mm pot with two knee points): BCM degree 3 and the automatically chosen model. "
        "Writes DIR/report.md, DIR/fit.png, DIR/fit_auto.png and DIR/calibration.json.",
    )
    p.add_argument("--out", metavar="DIR", default="out/demo", help="output directory (default out/demo)")
    p.add_argument("--sweep", metavar="SWEEP.csv", help="use this sweep instead of the bundled example")
    p.set_defaults(func=run)


def _row(name, r, floors):
    floor = floors["curve_floor"]
    return "| %s | %s %d | %d | %.1f | %.1f | %s | %s | %.1f |" % (
        name,
        r.model,
        r.order,
        r.n_params,
        1000 * r.rms,
        1000 * r.max_abs,
        "%.2f" % (r.rms / floor) if floor else "-",
        "yes" if r.monotone else "NO",
        1000 * r.fit_seconds,
    )


def _calibration(out_dir, fit, sweep, say):
    """Write both pot sections from the chosen fit; returns (path, crc, fixed_check) or a reason."""
    from host.calibration.file import CalibrationFile, pot_section
    from host.fitting.sweep import adc_bits_of

    path = out_dir / "calibration.json"
    bits = adc_bits_of(sweep.x)
    if bits is None:
        return "raw does not look like ADC codes"
    try:
        cal = CalibrationFile(path)
        if path.exists():  # a demo starts from nothing, never from an older run's sections: the old file kept aside
            say("kept the previous calibration as %s" % cal.keep_previous())
            path.unlink()
        crc = cal.set_sections(dict((pot, pot_section(fit, bits)) for pot in ("pot1", "pot2")))
    except UserError as exc:
        return str(exc)
    say("wrote %s (crc32 %08x)" % (path, crc))
    return path, crc, cal.read()["pot1"].get("fixed_check")


def run(args):
    from host.fitting.pot_fit import fit_sweep
    from host.fitting.example_sweep import DEFAULT_PATH, write_sweep
    from host.fitting.plots import plot_fit
    from host.fitting.sweep import load_sweep

    say = note  # progress to stderr; the report's path (the result) to stdout

    out_dir = Path(args.out)
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError("cannot create %s: %s" % (out_dir, exc.strerror)) from None
    source = Path(args.sweep) if args.sweep else DEFAULT_PATH
    if not args.sweep and not source.exists():  # an installed copy without examples/: rebuild it
        source = write_sweep(out_dir / "sweep_60mm.csv")
        say("regenerated the example sweep at %s" % source)
    sweep = load_sweep(source)
    say("[1/4] loaded %s: %s" % (source, sweep.describe()))
    bcm, floors, _ = fit_sweep(sweep, "bcm", 3)
    say("[2/4] BCM degree 3: rms %.1f um, max %.1f um in %.0f ms"
        % (1000 * bcm.rms, 1000 * bcm.max_abs, 1000 * bcm.fit_seconds))
    auto, _, reason = fit_sweep(sweep, "auto", progress=lambda m: say("      " + m))
    say("[3/4] auto: %s" % reason)
    plot_fit(out_dir / "fit.png", sweep.x, sweep.y, bcm, noise=floors["noise_floor"], direction=sweep.direction)
    plot_fit(out_dir / "fit_auto.png", sweep.x, sweep.y, auto, noise=floors["noise_floor"], direction=sweep.direction)
    cal = _calibration(out_dir, auto, sweep, say)
    report = out_dir / "report.md"
    report.write_text(_report(source, sweep, floors, bcm, auto, reason, cal))
    say("[4/4] wrote %s, %s, %s" % (out_dir / "fit.png", out_dir / "fit_auto.png", report))
    output("report: %s" % report)
    return DONE


def _report(source, sweep, floors, bcm, auto, reason, cal):
    nf, h, cf = floors["noise_floor"], floors["hysteresis"], floors["curve_floor"]
    lines = [
        "# lsea-kit demo: calibrating a 60 mm potentiometer",
        "",
        "Sweep: `%s`: %s." % (source, sweep.describe()),
        "",
        "- noise floor (scatter about the curve, per direction): %.1f um" % (1000 * nf),
        "- hysteresis (half the gap between the two directions): %.1f um" % (1000 * abs(h)),
        "- the floor one calibration curve can reach (both combined): %.1f um" % (1000 * cf),
        "",
        "| fit | model | parameters | rms (um) | max (um) | rms / floor | monotone | fit (ms) |",
        "| --- | --- | --- | --- | --- | --- | --- | --- |",
        _row("paper's BCM", bcm, floors),
        _row("auto", auto, floors),
        "",
        "Auto selection: %s." % reason,
        "",
        "Figures: `fit.png` (BCM degree 3) and `fit_auto.png` (auto): data and curve on top, "
        "residuals in um below with the noise floor band.",
        "",
    ]
    if isinstance(cal, tuple):
        path, crc, check = cal
        lines.append("Calibration file: `%s` (crc32 %08x): both pot sections hold the auto fit, exported "
                     "to the firmware's integer form" % (path.name, crc))
        if check:
            lines[-1] += " (%s; worst error vs float64 over every code %.2f um, bound %.2f um; largest "\
                         "intermediate 2^%.2f)." % (check["kind"], check["max_error"], check["bound"],
                                                    check["max_intermediate_log2"])
        else:
            lines[-1] += "."
    else:
        lines.append("Calibration file: not written: %s." % cal)
    lines += ["", "Reproduce: `host demo --out DIR`, or `host fit %s --model auto --plot fit.png`." % source.name, ""]
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit("run as: host demo")
