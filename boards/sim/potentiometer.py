"""A simulated linear potentiometer: its inherent nonlinearity and its mounting error.

Output fraction (0..1 of the supply) for a true carriage position x in mm:

    s = x + e(x)                      wiper travel on the track (mounting/geometry error e)
    u = (s - zero_mm) / track_mm      normalised track position
    fraction = g(u)                   inherent nonlinearity with two knee points

g is piecewise linear through four points (0, g0), (u1, g1), (u2, g2), (1, g3) with both
corners rounded by a parabola over +-knee_halfwidth, so g is smooth (C1) and strictly increasing
when the three slopes are positive. Outside the track the wiper sits on the end contacts.

e(x) = sum_k c_k v**k (k = 0..4) with v = (x - centre_mm) / half_span_mm: a smooth mounting
error (the pot body bowed and tilted against the carriage it follows), small in the middle of the
stroke and growing toward both ends. The two pots get different e, so with no load they disagree
by Df(x) = e1(x) - e2(x), shaped like SPEC section 3 (docs/simulated-actuator.md gives the split).
Only + - * / are used, so the values are bit-identical under MicroPython and CPython.
"""


class Potentiometer:
    def __init__(self, p):
        self.zero_mm = float(p["zero_mm"])
        self.track_mm = float(p["track_mm"])
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
        m = p["mount_error"]
        self.centre = float(m["centre_mm"])
        self.half = float(m["half_span_mm"])
        self.coeffs = [float(c) for c in m["coeffs_mm"]]

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

    def fraction(self, x):
        return self.curve((self.wiper_mm(x) - self.zero_mm) / self.track_mm)
