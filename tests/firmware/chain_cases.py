"""The measurement chain as the firmware computes it, for every input: run under the real
MicroPython (and CPython), compared by tests/firmware/test_measurement_chain.py with the host's integer
reference computed in CPython from the same calibration file.
"""


def _measurement(cal_path, tabulate=True):
    from firmware.calibration import load_calibration
    from firmware.measurement import Measurement

    return Measurement(load_calibration(cal_path), tabulate)


def case_chain(cal_path, bits, fixed, tabulate=True):
    """For each fixed code f: every code c of pot1 with pot2 at f, then every code of pot2 with
    pot1 at f. Each record: D1 (pot1's conversion alone), D1* (after Df), D2, d, F. With
    `tabulate` D1* and D2 come from the boot-time per-code tables, else from the curves."""
    m = _measurement(cal_path, tabulate)
    assert (m.t1 is not None) == tabulate
    out = []
    for f in fixed:
        for sweep in (1, 2):
            rows = []
            c = 0
            while c < 1 << bits:
                r1, r2 = (c, f) if sweep == 1 else (f, c)
                m.update(r1, r2)
                rows.append([m.conv1(r1, m.k1), m.d1, m.d2, m.defl, m.force])
                c += 1
            out.append(rows)
    return out


def case_polys(cal_path, margin):
    """Df, F0 and d(F0) at every integer input of their declared ranges, and `margin` beyond
    each end (where the input is clamped)."""
    m = _measurement(cal_path)
    out = {}
    for name, k in (("df", m.k_df), ("force", m.k_force), ("force_inverse", m.k_force_inv)):
        lo = k[2] - margin
        hi = k[3] + margin
        vals = []
        x = lo
        while x <= hi:
            vals.append(m.poly(x, k))
            x += 1
        out[name] = [lo, hi, vals]
    return out
