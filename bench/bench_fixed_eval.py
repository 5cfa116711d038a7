"""Figures for docs/fixed-point.md: accuracy, worst intermediate and speed of the firmware's math.

    .venv/bin/python bench/bench_fixed_eval.py [--random N]

Accuracy is measured at every ADC code against float64 (host/calibration/fixed_export.py), the worst
intermediate by running the firmware functions on tracking ints, and the speed under the real
MicroPython unix port (x64; a board is 10-50x slower, scale accordingly).
"""

import argparse
import time

import numpy as np

from host.fitting.example_sweep import simulate_sweep
from host.calibration.fixed_export import export_bcm3, export_curve_table, export_poly, export_pwl
from host.fitting.rational_bezier import evaluate, fit_bcm
from host.fitting.sweep import load_sweep
from testkit.interpreters import REPO, run_micropython

KNEE = {"lx": 60.0, "rx": 3950.0, "weights": [1.0, 12.0, 12.0, 1.0], "handles": [0.0, 1.5, 58.5, 60.0]}
POLYS = {
    "Df_hat(D1) um->um": ([-1.922222e-6, 2.632e-4, -1.63e-2, 0.46, -4.6], (0.0, 60.0)),
    "F0(d) um->mN": ([0.65, 12.37, 2.08], (-2.0, 6.0)),
    "d(F0) mN->um": ([0.00091, 0.070, -0.18], (-20.0, 80.0)),
}


def row(name, k, unit="um"):
    print(
        "  %-34s max error %6.3f %s (bound %6.3f)  worst intermediate 2**%.3f  %d words"
        % (name, k.max_error, unit, k.bound, np.log2(max(k.max_intermediate, 1)), len(k))
    )


def sweep_fits():
    _, raw, ref, _ = simulate_sweep()
    keep = (raw > 0) & (raw < 4095)
    order = np.argsort(raw[keep], kind="stable")
    x, y = raw[keep][order].astype(float), ref[keep][order]
    return x, y


def accuracy(n_random):
    print("accuracy against float64 at every 12-bit code (bound 0.5 LSB = 0.5 * span / 4096):")
    row("bcm3, a knee curve like the paper's Fig. 2c", export_bcm3(KNEE, 12))
    x, y = sweep_fits()
    t0 = time.perf_counter()
    fit3 = fit_bcm(x, y, 3)
    row("bcm3, fit to host.fitting.example_sweep", export_bcm3(fit3.coefficients, 12))
    fit5 = fit_bcm(x, y, 5)
    k5 = export_curve_table(fit5, 12)
    row("table of the degree-5 fit (%d knots)" % k5[0], k5)
    row("pwl, 4 knots", export_pwl([100, 500, 3000, 3900], [0, 5, 55, 60], 12))
    for path in sorted((REPO.parent / "shared" / "realdata").glob("*.csv")):
        sweep = load_sweep(path)
        fit = fit_bcm(sweep.x, sweep.y, 3)
        unit_um = 60000 / np.ptp(fit(np.arange(4096)))  # read the divider as a 60 mm pot
        row("bcm3, " + path.stem[:28], export_bcm3(fit.coefficients, 12, unit_um=unit_um))
    print("  (fits took %.1f s)" % (time.perf_counter() - t0))
    rng = np.random.default_rng(1)
    errs, ratios, peaks, refused, spans = [], [], [], 0, []
    for _ in range(n_random):
        # the fitter's whole box: w_0 = 1, every other weight in [1/60, 60]; sorted handles in
        # the widened 60 mm range make a monotone curve, whose span may be anything up to 72 mm
        lx, ux = rng.uniform(0, 400), rng.uniform(3600, 4095)
        w = [1.0, *(60.0 ** rng.uniform(-1, 1, 3))]
        c = {"lx": lx, "rx": ux - lx, "weights": w, "handles": list(np.sort(rng.uniform(-6, 66, 4)))}
        k = export_bcm3(c, 12, max_error_um=1e9)
        fine = evaluate(c, np.linspace(0, 4095, 4095 * 16 + 1)) * 1000
        span = fine.max() - fine.min()
        errs.append(k.max_error)
        ratios.append(k.max_error / (0.5 * span / 4096))
        peaks.append(k.max_intermediate)
        spans.append(span)
        refused += k.max_error > 0.5 * span / 4096
    over = [s for s, r in zip(spans, ratios) if r > 1]
    print(
        "  %d random monotone bcm3 curves (w_0 = 1, w_i in [1/60, 60], sorted handles in -6..66 mm): error median "
        "%.2f um, max %.2f um; error/bound median %.2f, max %.2f; %d over the bound (refused%s); worst intermediate "
        "2**%.3f"
        % (n_random, np.median(errs), np.max(errs), np.median(ratios), np.max(ratios), refused,
           ": spans %s mm" % ", ".join("%.1f" % (s / 1000) for s in over) if over else "", np.log2(max(peaks)))
    )
    for name, (coeffs, rng_mm) in POLYS.items():
        row("poly " + name, export_poly(coeffs, *rng_mm, 1000, 1000), "units")


def speed():
    x, y = sweep_fits()
    k3 = export_bcm3(fit_bcm(x, y, 3).coefficients, 12)
    kd = export_curve_table(lambda v: evaluate(KNEE, v), 12, n_points=4096, x_range=(0, 4095))
    kp = export_pwl([100, 500, 3000, 3900], [0, 5, 55, 60], 12)
    kdf = export_poly(*POLYS["Df_hat(D1) um->um"][0:1], 0.0, 60.0, 1000, 1000)
    def bytecode(module):  # the same source without the @native decorator
        text = (REPO / "firmware" / (module + ".py")).read_text()
        return "\n".join(line for line in text.splitlines() if not line.startswith("@micropython.native"))

    source = """
import time
from array import array
from firmware.bcm_fixed import bcm3
from firmware.pwl_fixed import pwl
from firmware.poly_fixed import poly
plain = {}
for text in (%r, %r, %r):
    exec(text, plain)
def bench(f, k, step):
    n = 20000
    best = 1e9
    for rep in range(5):
        i = 0
        t = time.ticks_us()
        while i < n:
            f((i * step) & 4095, k)
            i += 1
        best = min(best, time.ticks_diff(time.ticks_us(), t) / n)
    return best
def empty(x, k):
    return x
def df(x, k):
    return poly(x * 14, k)
def df_plain(x, k):
    return plain['poly'](x * 14, k)
K3 = array('i', %r); KD = array('i', %r); KP = array('i', %r); KDF = array('i', %r)
same = all(bcm3(c, K3) == plain['bcm3'](c, K3) and pwl(c, KD) == plain['pwl'](c, KD) for c in range(4096))
print('call overhead (empty function) %%.2f us' %% bench(empty, K3, 7))
print('native (as shipped) vs bytecode, identical results at every code: %%s' %% same)
print('bcm3 %%.2f us (bytecode %%.2f us)' %% (bench(bcm3, K3, 7), bench(plain['bcm3'], K3, 7)))
print('pwl 4-knot table %%.2f us (bytecode %%.2f us)' %% (bench(pwl, KP, 7), bench(plain['pwl'], KP, 7)))
print('pwl 4096-knot table %%.2f us (bytecode %%.2f us)' %% (bench(pwl, KD, 7), bench(plain['pwl'], KD, 7)))
print('poly degree 4 (Df), incl. a wrapper call %%.2f us (bytecode %%.2f us)' %% (bench(df, KDF, 7), bench(df_plain, KDF, 7)))
""" % (bytecode("bcm_fixed"), bytecode("pwl_fixed"), bytecode("poly_fixed"), list(k3), list(kd), list(kp), list(kdf))
    print("speed under MicroPython (unix port, x64), best of 5 x 20,000 calls:")
    for line in run_micropython(source).stdout.splitlines():
        print("  " + line)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--random", type=int, default=100, help="random bcm3 curves to measure (default 100)")
    args = parser.parse_args()
    accuracy(args.random)
    speed()


if __name__ == "__main__":
    main()
