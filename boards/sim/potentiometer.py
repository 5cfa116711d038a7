"""A simulated linear potentiometer: its inherent nonlinearity and its mounting error.

Output fraction (0..1 of the supply) for a true carriage position x in mm:

    s = x + e(x)                      wiper travel on the track (mounting/geometry error e)
    u = (s - zero_mm) / track_mm      normalised track position
    fraction = g(u)                   inherent nonlinearity with two knee points

g is piecewise linear through four points (0, g0), (u1, g1), (u2, g2), (1, g3) with both
corners rounded by a parabola over +-knee_halfwidth, so g is smooth (C1) and strictly increasing
when the three slopes are positive. Outside the track the wiper sits on the end contacts.

Or, with "curve_table" instead of "curve"/"knee_halfwidth", g is the linear interpolation of a
measured table, so a user can try the calibration on the pot (or ADC) they have:

    "curve_table": {"csv": "sweep.csv", "x": "reference", "y": "raw", "y_full_scale": 4095}
    "curve_table": [[u0, g0], [u1, g1], ...]

A CSV's x column (a position, a voltage: any unit) is normalised to u in 0..1 over its range and
its y column divided by y_full_scale (e.g. a pot's sweep: reference mm and raw code; a measured
ADC transfer curve: reference volts and raw code). Rows are sorted by x, rows with the same x
averaged, and where noise makes g fall as u rises the closest non-decreasing curve is taken
(isotonic regression); a clipped end stays flat, as a real ADC's is.

e(x) = sum_k c_k v**k (k = 0..4) with v = (x - centre_mm) / half_span_mm: a smooth mounting
error (the pot body bowed and tilted against the carriage it follows), small in the middle of the
stroke and growing toward both ends. The two pots get different e, so with no load they disagree
by Df(x) = e1(x) - e2(x), shaped like the paper's section 3 (docs/simulated-actuator.md gives the split).
Only + - * / are used, so the values are bit-identical under MicroPython and CPython.
"""


def _read_csv_columns(path, x_name, y_name):
    """(xs, ys) floats of two named columns of a CSV file with a header row (MicroPython-safe)."""
    with open(path) as f:
        header = f.readline().strip().split(",")
        try:
            ix = header.index(x_name)
            iy = header.index(y_name)
        except ValueError:
            raise ValueError("%s: needs columns %r and %r, has %s" % (path, x_name, y_name, ",".join(header)))
        xs = []
        ys = []
        for line in f:
            cells = line.strip().split(",")
            if len(cells) <= max(ix, iy) or not cells[ix] or not cells[iy]:
                continue
            xs.append(float(cells[ix]))
            ys.append(float(cells[iy]))
    return xs, ys


def _isotonic(g):
    """The non-decreasing sequence closest to g in least squares (pool adjacent violators): a
    noisy sweep's readings fall here and there although the pot under them never does."""
    blocks = []  # [mean, count]
    for v in g:
        blocks.append([v, 1])
        while len(blocks) > 1 and blocks[-2][0] > blocks[-1][0]:
            m2, n2 = blocks.pop()
            m1, n1 = blocks[-1]
            blocks[-1] = [(m1 * n1 + m2 * n2) / (n1 + n2), n1 + n2]
    out = []
    for m, n in blocks:
        out.extend([m] * n)
    return out


def table_curve(spec):
    """(u, g) lists of a "curve_table" spec (see the module docstring): u from 0 to 1, strictly
    increasing; g within 0..1 and never falling."""
    if isinstance(spec, dict):
        xs, ys = _read_csv_columns(spec["csv"], spec.get("x", "reference"), spec.get("y", "raw"))
        full = float(spec.get("y_full_scale", 4095))
        rows = sorted(zip(xs, ys))
    else:
        rows = sorted((float(q[0]), float(q[1])) for q in spec)
        full = 1.0
    if len(rows) < 2 or rows[-1][0] <= rows[0][0]:
        raise ValueError("curve_table needs at least two distinct x values")
    x0 = rows[0][0]
    span = rows[-1][0] - x0
    u = []
    g = []
    i = 0
    while i < len(rows):  # average the rows that share an x
        j = i
        total = 0.0
        while j < len(rows) and rows[j][0] == rows[i][0]:
            total += rows[j][1]
            j += 1
        u.append((rows[i][0] - x0) / span)
        g.append(total / (j - i) / full)
        i = j
    g = _isotonic(g)
    if not (0.0 <= g[0] and g[-1] <= 1.0):
        raise ValueError("curve_table values must lie within 0..1 of full scale")
    return u, g


class Potentiometer:
    def __init__(self, p):
        self.zero_mm = float(p["zero_mm"])
        self.track_mm = float(p["track_mm"])
        m = p["mount_error"]
        self.centre = float(m["centre_mm"])
        self.half = float(m["half_span_mm"])
        self.coeffs = [float(c) for c in m["coeffs_mm"]]
        self.table = None
        if "curve_table" in p:
            self.table = table_curve(p["curve_table"])
            return
        pts = p["curve"]
        if len(pts) != 4:
            raise ValueError("pot curve needs 4 points: (0, g0), two knees, (1, g3)")
        self.u = [float(q[0]) for q in pts]
        self.g = [float(q[1]) for q in pts]
        self.slope = []
        for i in range(3):
            du = self.u[i + 1] - self.u[i]
            dg = self.g[i + 1] - self.g[i]
            if du <= 0 or dg <= 0:
                raise ValueError("pot curve must be strictly increasing in u and g")
            self.slope.append(dg / du)
        self.h = float(p["knee_halfwidth"])
        if not (0 < self.h and self.u[1] + self.h < self.u[2] - self.h and self.u[1] - self.h > 0
                and self.u[2] + self.h < 1):
            raise ValueError("knee_halfwidth too wide for the knee positions")

    def mount_error_mm(self, x):
        v = (x - self.centre) / self.half
        c = self.coeffs
        e = 0.0
        k = len(c) - 1
        while k >= 0:  # Horner
            e = e * v + c[k]
            k -= 1
        return e

    def wiper_mm(self, x):
        """Where on the track (in stroke mm) the wiper sits when the carriage is at x."""
        return x + self.mount_error_mm(x)

    def curve(self, u):
        """Inherent output fraction g(u) for normalised track position u (clamped to the track)."""
        if self.table is not None:
            return self._table_curve(u)
        if u <= 0.0:
            return self.g[0]
        if u >= 1.0:
            return self.g[3]
        h = self.h
        uk1 = self.u[1]
        uk2 = self.u[2]
        s0, s1, s2 = self.slope
        if u < uk1 + h:
            line = self.g[1] + s0 * (u - uk1)
            if u > uk1 - h:
                w = u - uk1 + h
                line += (s1 - s0) * w * w / (4.0 * h)
            return line
        if u < uk2 - h:
            return self.g[1] + s1 * (u - uk1)
        line = self.g[2] + s1 * (u - uk2)
        if u < uk2 + h:
            w = u - uk2 + h
            return line + (s2 - s1) * w * w / (4.0 * h)
        return self.g[2] + s2 * (u - uk2)

    def _table_curve(self, u):
        tu, tg = self.table
        if u <= 0.0:
            return tg[0]
        if u >= 1.0:
            return tg[-1]
        lo = 0
        hi = len(tu) - 1
        while hi - lo > 1:  # tu[lo] <= u < tu[hi]
            mid = (lo + hi) // 2
            if tu[mid] <= u:
                lo = mid
            else:
                hi = mid
        return tg[lo] + (tg[hi] - tg[lo]) * (u - tu[lo]) / (tu[hi] - tu[lo])

    def fraction(self, x):
        return self.curve((self.wiper_mm(x) - self.zero_mm) / self.track_mm)
