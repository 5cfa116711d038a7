"""Measurement: ADC codes to D1, D2, the Df-corrected D1*, the spring deformation and the force.

    D1 = conv(pot1 code)   D2 = conv(pot2 code)       (bcm3 or pwl, per pot, from the calibration)
    D1* = D1 - Df_hat(D1)                             (poly, when the Df step was calibrated)
    d = D1* - D2                                      (um)
    F = F0(d) + h * s                                 (poly, mN, when the force step was calibrated)

F is the force the load feels. Without a `friction` section it is the spring force F0(d). With
one (h, the output block's Coulomb friction, mN), the block sits between the spring and the load
and its friction is a play (backlash) operator in force: while the block sticks, the load's force
stays put as the spring force changes by up to +-h; once the spring force leaves that band the
block slides and the load follows it at a distance h. So F = play_h(F0(d)), on F0(d) low-passed
over ~64 steps: a play operator follows the extremes of its input, so the pots' noise (~0.2 N of
F0 per step) would walk the band; filtered over 32 steps it still biased the estimate by up to
0.1 N, over 64 steps by a third of that, and over 128 the lag costs more than it gains. `dir` records which edge moved
last (+1: the spring force fell, the block slid toward 0 mm; -1: toward 60 mm). A force target
becomes one deformation target per edge (`deformation_targets`, F0 = target - h * s): the
controller drives the spring to the edge from which the load's force moves toward the target.
The integer math is B's (bcm_fixed, pwl_fixed, poly_fixed); it allocates nothing and keeps its
intermediates within +-2**30. Positions are clamped to +-STROKE_CLAMP_UM so that d and every
error the controllers form from them stay within +-2**17; the filtered force is in mN * 32.
"""

from firmware.portable import const

STROKE_CLAMP_UM = const(65535)
FORCE_CLAMP_MN = const(1000000)

try:
    from firmware.bcm_fixed import bcm3
    from firmware.poly_fixed import poly
    from firmware.pwl_fixed import pwl

    MATH_ERROR = None
except ImportError as exc:  # B's modules not installed on this board yet
    bcm3 = pwl = poly = None
    MATH_ERROR = "fixed-point math modules missing (%s)" % exc


def _clamp_um(x):
    if x > STROKE_CLAMP_UM:
        return STROKE_CLAMP_UM
    if x < -STROKE_CLAMP_UM:
        return -STROKE_CLAMP_UM
    return x


def _converter(kind):
    if kind == "bcm3":
        return bcm3
    if kind == "pwl":
        return pwl
    raise ValueError("unknown pot conversion %r" % (kind,))


class Measurement:
    """Holds the calibration constants and the latest converted values (all ints)."""

    def __init__(self, calibration):
        if MATH_ERROR is not None:
            raise ValueError(MATH_ERROR)
        kind1, self.k1 = calibration.pot1
        kind2, self.k2 = calibration.pot2
        self.conv1 = _converter(kind1)
        self.conv2 = _converter(kind2)
        self.poly = poly
        self.k_df = calibration.df
        self.k_force = calibration.force
        self.k_force_inv = calibration.force_inverse
        fr = getattr(calibration, "friction", None)  # [h mN] or None
        self.fric = fr[0] if fr is not None else 0
        self.d1 = 0  # D1*, um (D1 when Df is not calibrated)
        self.d2 = 0
        self.defl = 0
        self.force = 0
        self.dir = 0  # which band edge moved last (+1: toward 0 mm, -1: toward 60 mm); diagnostic
        self.fs32 = 0  # spring force F0(d) low-passed, mN * 32
        self.out32 = 0  # the play operator's output (the load's force), mN * 32
        self.primed = False

    def missing_for(self, mode_name):
        """None when `mode_name` can run with this calibration, else the reason it cannot."""
        if mode_name == "force":
            if self.k_df is None:
                return "force mode needs the Df (assembly) calibration"
            if self.k_force is None or self.k_force_inv is None:
                return "force mode needs the force calibration F0(d) and d(F0)"
        return None

    def update(self, raw1, raw2):
        d1 = _clamp_um(self.conv1(raw1, self.k1))
        if self.k_df is not None:
            d1 = _clamp_um(d1 - self.poly(d1, self.k_df))
        d2 = _clamp_um(self.conv2(raw2, self.k2))
        self.d1 = d1
        self.d2 = d2
        self.defl = d1 - d2
        if self.k_force is not None:
            f = self.poly(self.defl, self.k_force)
            self.force = self._load_force(f) if self.fric else f

    def _load_force(self, spring_mN):
        # A file's F0 may reach 2**29 mN (poly_fixed's bound); 1 kN is far beyond any spring
        # here and keeps x << 5 and the differences below within 2**30 (h <= 10 N).
        if spring_mN > FORCE_CLAMP_MN:
            spring_mN = FORCE_CLAMP_MN
        elif spring_mN < -FORCE_CLAMP_MN:
            spring_mN = -FORCE_CLAMP_MN
        x = spring_mN << 5
        if not self.primed:
            self.fs32 = x
            self.out32 = x
            self.primed = True
        f = self.fs32 + ((x - self.fs32) >> 6)
        self.fs32 = f
        h = self.fric << 5
        if f > self.out32 + h:
            self.out32 = f - h
            self.dir = -1
        elif f < self.out32 - h:
            self.out32 = f + h
            self.dir = 1
        return self.out32 >> 5

    def deformation_for(self, force_mN):
        """Target deformation for a target spring force, through the fitted inverse d(F0)."""
        return _clamp_um(self.poly(force_mN, self.k_force_inv))

    def deformation_targets(self, force_mN, out):
        """Fill out[s + 1] (s = -1, 0, +1) with the deformation that makes the load feel
        `force_mN` when the block's friction acts with direction s (see the module docstring)."""
        s = -1
        while s <= 1:
            out[s + 1] = self.deformation_for(force_mN - self.fric * s)
            s += 1
