"""Measurement: ADC codes to D1, D2, the Df-corrected D1*, the spring deformation and the force.

    D1 = conv(pot1 code)   D2 = conv(pot2 code)       (bcm3 or pwl, per pot, from the calibration)
    D1* = D1 - Df_hat(D1)                             (poly or pwl table, when the Df step was calibrated)
    d = (D1* - D2 - z(D2)) * g(D2)                   (um; z, g: deformation offset and gain tables, 0 and 1 without)
    F = F0(d) + h * s                                 (poly or pwl table, mN, when the force step was calibrated)

g: the reference the pots are calibrated against reads each pot's wiper, so pot 2's curve keeps
pot 2's mounting error, and once Df is taken out D1* - D2 is the true deformation times the slope
of pot 2's curve where the block is (a few % apart along the stroke on a bowed mount). The force
step measures F0 at one place; g (1 there) is measured along the stroke with a constant load
(host/guided/gain_sweep.py), so F0 holds elsewhere. z is what D1* - D2 still reads at no load
where the block is (the Df fit's residual, tens of um: at 15-30 N/mm a few tenths of a newton
that differ from place to place), measured by the same step's no-load sweep.

F is the force the load feels. Without a `friction` section it is the spring force F0(d). With
one (h, the output block's Coulomb friction, mN), the block sits between the spring and the load
and its friction is a play (backlash) operator in force: while the block sticks, the load's force
stays put as the spring force changes by up to +-h; once the spring force leaves that band the
block slides and the load follows it at a distance h. So F = play_h(F0(d)), on F0(d) low-passed
over 64 steps: a play operator follows the extremes of its input, so the pots' noise (~0.2 N of
F0 per step) would walk the band (docs/firmware.md says why 64). `dir` records which edge moved
last (+1: the spring force fell, the block slid toward 0 mm; -1: toward 60 mm). A force target
becomes one deformation target per edge (`deformation_targets`, F0 = target - h * s): the
controller drives the spring to the edge from which the load's force moves toward the target.
The integer math (bcm_fixed, pwl_fixed, poly_fixed) allocates nothing and keeps its
intermediates within +-2**30. Positions are clamped to +-STROKE_CLAMP_UM so that d and every
error the controllers form from them stay within +-2**17; the filtered force is in mN * 32.
The values the step produces live in one int32 block, `Measurement.st` (indices below); d1, d2,
defl, force, dir, fs32 and out32 are properties over it.
"""

from firmware.bcm_fixed import bcm3
from firmware.poly_fixed import poly
from array import array

from firmware.portable import const, ptr16, ptr32, word_property, zeros
from firmware.pwl_fixed import FORCE_PWL_OFFSET, df_table_input, pwl

try:
    import micropython  # @micropython.viper is resolved by MicroPython's compiler
except ImportError:  # CPython
    from firmware import portable as micropython

STROKE_CLAMP_UM = const(65535)  # [copied-constants] protocol.POSITION_LIMIT_UM
_DF_PWL_OFFSET = const(32768)  # [copied-constants] pwl_fixed.DF_PWL_OFFSET
FORCE_CLAMP_MN = const(1000000)
_GAIN_CLAMP_UM = const(32767)  # |D1* - D2| before the gain: |d| * gain (<= 2**15) stays within 2**30

# [sign-fix] (docs/firmware.md, Viper idioms): a word that may be negative is read as ((v + _B29) & _M30) - _B29
_B29 = const(536870912)
_M30 = const(1073741823)

# Measurement.st
D1 = const(0)  # D1*, um (D1 when Df is not calibrated)
D2 = const(1)
DEFL = const(2)
FORCE = const(3)  # mN: the load's force (play operator) with friction, else F0(d)
DIR = const(4)  # which band edge moved last (+1: toward 0 mm, -1: toward 60 mm); diagnostic
FS32 = const(5)  # spring force F0(d) low-passed, mN * 32
OUT32 = const(6)  # the play operator's output (the load's force), mN * 32
PRIMED = const(7)  # 1 once FS32 and OUT32 start from a measured force
FRIC = const(8)  # the block's friction h, mN (0 without a friction section)
HAS_DF = const(9)
HAS_FORCE = const(10)
TABLES = const(11)  # 1 when D1* and D2 come from the per-code tables
LAST_CODE = const(12)  # the highest ADC code, 2**adc_bits - 1
BASE1 = const(13)  # the tables hold D - BASE as uint16
BASE2 = const(14)
FF_DUTY = const(15)  # the duty that holds the spring at the friction force (0: no feed-forward)
F_IN = const(16)  # added to d before F0 is evaluated: 0 for a polynomial, FORCE_PWL_OFFSET for a table
DF_IN = const(17)  # 1 when Df is a table: its input is (D1 >> 1) + DF_PWL_OFFSET (pwl_fixed.df_table_input)
FS_SHIFT = const(18)  # the spring force's low-pass: over 2**FS_SHIFT steps (filter_shift)
HAS_GAIN = const(19)  # 1 with a deformation gain table
HAS_OFFSET = const(20)  # 1 with a deformation offset table
WORDS = const(21)
TABLE_MAX_BITS = const(12)  # 2 x 4096 x 2 bytes = 16 KiB; wider ADCs evaluate the curves per step


def _clamp_um(x):
    if x > STROKE_CLAMP_UM:
        return STROKE_CLAMP_UM
    if x < -STROKE_CLAMP_UM:
        return -STROKE_CLAMP_UM
    return x


def adc_bits_of(kind, k):
    """The ADC width a pot's constants were exported for (their input shift says it)."""
    return (29 if kind == "bcm3" else 16) - k[1 if kind == "pwl" else 0]


def board_problem(calibration, board):
    """Why `calibration` cannot be used on `board` (a board file's dict), or None: it was made
    for another board, or for another ADC width. Checked before a Measurement is made from it:
    that evaluates every code of the width a pot's constants declare, and a bcm3 with input
    shift 0 declares 29 bits (2**29 codes: hours on a Cortex-M0, the board silent meanwhile)."""
    made_for = getattr(calibration, "board", None)
    if made_for is not None and made_for != board["name"]:
        return "calibration made for board %s, this board is %s" % (made_for, board["name"])
    for name, (kind, k) in (("pot1", calibration.pot1), ("pot2", calibration.pot2)):
        bits = adc_bits_of(kind, k)
        if bits != board["adc_bits"]:
            return "calibration made for a %d-bit ADC (%s), this board's is %d-bit" % (bits, name, board["adc_bits"])
    return None


def filter_shift(loop_hz):
    """log2 of the steps the spring force is averaged over before the play operator: 64 at 1 kHz
    and above (docs/firmware.md says why 64), the same 64 ms at a slower loop (16 steps at
    CircuitPython's 250 Hz), never fewer than 4 steps."""
    shift = 6
    while shift > 2 and loop_hz * 64 < 1000 << shift:  # 2**shift steps last longer than 64 ms
        shift -= 1
    return shift


def _converter(kind):
    if kind == "bcm3":
        return bcm3
    if kind == "pwl":
        return pwl
    raise ValueError("unknown pot conversion %r" % (kind,))


class Measurement:
    """Holds the calibration constants and the latest converted values (all ints)."""

    def __init__(self, calibration, tabulate=True, loop_hz=1000):
        kind1, self.k1 = calibration.pot1
        kind2, self.k2 = calibration.pot2
        self.adc_bits = adc_bits_of(kind1, self.k1)
        if adc_bits_of(kind2, self.k2) != self.adc_bits:
            raise ValueError("pot1 and pot2 were calibrated for different ADC widths")
        self.conv1 = _converter(kind1)
        self.conv2 = _converter(kind2)
        self.poly = poly
        self.k_df = calibration.df
        df_table = getattr(calibration, "df_kind", "poly") == "pwl"
        self.df_eval = pwl if df_table else poly
        self.df_table = df_table
        self.k_force = calibration.force
        self.k_force_inv = calibration.force_inverse
        # F0(d) and d(F0): polynomials, or tables (a spring pair whose preload ends inside the
        # force range changes stiffness at a point, which no low-order polynomial follows)
        table = getattr(calibration, "force_kind", "poly") == "pwl"
        self.force_eval = pwl if table else poly
        inv_table = getattr(calibration, "force_inverse_kind", "poly") == "pwl"
        self.inverse_eval = pwl if inv_table else poly
        self.inverse_in = FORCE_PWL_OFFSET if inv_table else 0
        self.k_gain = getattr(calibration, "gain", None)
        self.k_offset = getattr(calibration, "offset", None)
        self.gain_eval = pwl
        fr = getattr(calibration, "friction", None)  # [h mN], [h mN, ff duty] or None
        st = zeros(WORDS)
        self.st = st
        st[FRIC] = fr[0] if fr is not None else 0
        st[FF_DUTY] = fr[1] if fr is not None and len(fr) > 1 else 0
        st[F_IN] = FORCE_PWL_OFFSET if table else 0
        st[DF_IN] = 1 if df_table else 0
        st[HAS_DF] = 1 if self.k_df is not None else 0
        st[HAS_FORCE] = 1 if self.k_force is not None else 0
        st[HAS_GAIN] = 1 if self.k_gain is not None else 0
        st[HAS_OFFSET] = 1 if self.k_offset is not None else 0
        st[LAST_CODE] = (1 << self.adc_bits) - 1
        st[FS_SHIFT] = filter_shift(loop_hz)
        self._play = self._load_force  # bound once: found in the instance by viper's first look
        self.t1 = self.t2 = None
        self._scan(tabulate and self.adc_bits <= TABLE_MAX_BITS)

    def _scan(self, tabulate):
        """One pass over every ADC code at boot, each curve evaluated once per code.

        Refuses (ValueError) a pot curve whose position falls anywhere as its code rises: the
        firmware's convention is that both readings grow toward 60 mm, and a falling curve turns
        every closed loop round (a position target runs into the stroke end).

        With `tabulate`, also fills tables of D1* and D2 per code, made by the same integer
        functions the step would call (so the same bits as the host's) and then looked up by
        the step: two loads instead of two curve evaluations and the Df polynomial (~5000
        Cortex-M0 instructions a step). Each holds D - base as uint16 (2**adc_bits x 2 bytes:
        8 KiB at 12 bits), base centring the 65536 um window on the curve's two ends, with no
        scratch arrays (a board's heap is small). A curve that leaves its window is evaluated
        per step instead."""
        n = self.st[LAST_CODE] + 1
        conv1, conv2, k1, k2 = self.conv1, self.conv2, self.k1, self.k2
        t1 = t2 = None
        if tabulate:
            t1 = array("H", range(n))  # no throw-away list (portable.zeros)
            t2 = array("H", range(n))
            base1 = (self._d1(conv1(0, k1)) + self._d1(conv1(n - 1, k1))) // 2 - 32768
            base2 = (_clamp_um(conv2(0, k2)) + _clamp_um(conv2(n - 1, k2))) // 2 - 32768
        first1 = prev1 = conv1(0, k1)
        first2 = prev2 = conv2(0, k2)
        code = 0
        while code < n:
            r1 = conv1(code, k1)
            r2 = conv2(code, k2)
            if r1 < prev1 or r2 < prev2:  # (no tuple per code: boot must not fragment the heap)
                name, v, prev = ("pot1", r1, prev1) if r1 < prev1 else ("pot2", r2, prev2)
                raise ValueError("%s's curve falls at code %d (%d um after %d): positions must grow with the code"
                                 % (name, code, v, prev))
            prev1 = r1
            prev2 = r2
            if t1 is not None:
                v1 = self._d1(r1) - base1
                v2 = _clamp_um(r2) - base2
                if 0 <= v1 <= 65535 and 0 <= v2 <= 65535:
                    t1[code] = v1
                    t2[code] = v2
                else:
                    t1 = t2 = None  # out of the window: keep checking, evaluate per step
            code += 1
        for name, first, last in (("pot1", first1, prev1), ("pot2", first2, prev2)):
            if last <= first:
                raise ValueError("%s's curve does not rise over the ADC's codes" % name)
        if t1 is not None:
            self.t1 = t1
            self.t2 = t2
            st = self.st
            st[BASE1] = base1
            st[BASE2] = base2
            st[TABLES] = 1

    def _d1(self, raw_um):
        """D1* from pot 1's curve value: clamped, less the Df correction when calibrated."""
        d1 = _clamp_um(raw_um)
        if self.k_df is not None:
            d1 = _clamp_um(d1 - self.df_eval(df_table_input(d1) if self.df_table else d1, self.k_df))
        return d1

    d1 = word_property(D1)
    d2 = word_property(D2)
    defl = word_property(DEFL)
    force = word_property(FORCE)
    dir = word_property(DIR)
    fric = word_property(FRIC)
    fs32 = word_property(FS32)
    out32 = word_property(OUT32)

    def missing_for(self, mode_name):
        """None when `mode_name` can run with this calibration, else the reason it cannot."""
        if mode_name == "force":
            if self.k_df is None:
                return "force mode needs the Df (assembly) calibration"
            if self.k_force is None or self.k_force_inv is None:
                return "force mode needs the force calibration F0(d) and d(F0)"
        return None

    @micropython.viper
    def update(self, raw1: int, raw2: int):
        s = ptr32(self.st)
        if s[TABLES]:
            last = s[LAST_CODE]
            if raw1 > last:
                raw1 = last
            elif raw1 < 0:
                raw1 = 0
            if raw2 > last:
                raw2 = last
            elif raw2 < 0:
                raw2 = 0
            # ptr16 loads zero-extend on every port, and the entries are never negative
            d1 = int(ptr16(self.t1)[raw1]) + (((s[BASE1] + _B29) & _M30) - _B29)
            d2 = int(ptr16(self.t2)[raw2]) + (((s[BASE2] + _B29) & _M30) - _B29)
        else:  # what _scan() tabulates, evaluated now
            d1 = int(self.conv1(raw1, self.k1))
            if d1 > STROKE_CLAMP_UM:
                d1 = STROKE_CLAMP_UM
            elif d1 < -STROKE_CLAMP_UM:
                d1 = -STROKE_CLAMP_UM
            if s[HAS_DF]:
                x = d1
                if s[DF_IN]:
                    x = (d1 >> 1) + _DF_PWL_OFFSET
                d1 = d1 - int(self.df_eval(x, self.k_df))
                if d1 > STROKE_CLAMP_UM:
                    d1 = STROKE_CLAMP_UM
                elif d1 < -STROKE_CLAMP_UM:
                    d1 = -STROKE_CLAMP_UM
            d2 = int(self.conv2(raw2, self.k2))
            if d2 > STROKE_CLAMP_UM:
                d2 = STROKE_CLAMP_UM
            elif d2 < -STROKE_CLAMP_UM:
                d2 = -STROKE_CLAMP_UM
        s[D1] = d1
        s[D2] = d2
        d = d1 - d2
        at = (d2 >> 1) + _DF_PWL_OFFSET  # a table over D2 takes D2 as a Df table takes D1
        if s[HAS_OFFSET]:  # what Df left where the block is (module docstring)
            d = d - int(self.gain_eval(at, self.k_offset))
        if s[HAS_GAIN]:  # the slope of pot 2's curve where the block is, taken out
            if d > _GAIN_CLAMP_UM:
                d = _GAIN_CLAMP_UM
            elif d < -_GAIN_CLAMP_UM:
                d = -_GAIN_CLAMP_UM
            d = (d * int(self.gain_eval(at, self.k_gain)) + 8192) >> 14
        s[DEFL] = d
        if not s[HAS_FORCE]:
            return
        f = int(self.force_eval(d + s[F_IN], self.k_force))
        s[FORCE] = int(self._play(f)) if s[FRIC] else f

    @micropython.viper
    def _load_force(self, f: int) -> int:
        """The load's force: a play operator of width h on F0(d) low-passed over 2**FS_SHIFT steps."""
        s = ptr32(self.st)
        # A file's F0 may reach 2**29 mN (poly_fixed's bound); 1 kN is far beyond any spring
        # here and keeps f << 5 and the differences below within 2**30 (h <= 10 N).
        if f > FORCE_CLAMP_MN:
            f = FORCE_CLAMP_MN
        elif f < -FORCE_CLAMP_MN:
            f = -FORCE_CLAMP_MN
        x = f << 5
        if not s[PRIMED]:
            s[FS32] = x
            s[OUT32] = x
            s[PRIMED] = 1
        fs = ((s[FS32] + _B29) & _M30) - _B29
        fs = fs + ((x - fs) >> s[FS_SHIFT])
        s[FS32] = fs
        h = s[FRIC] << 5
        out = ((s[OUT32] + _B29) & _M30) - _B29
        if fs > out + h:
            out = fs - h
            s[DIR] = -1
        elif fs < out - h:
            out = fs + h
            s[DIR] = 1
        s[OUT32] = out
        return out >> 5

    def deformation_for(self, force_mN):
        """Target deformation for a target spring force, through the fitted inverse d(F0)."""
        return _clamp_um(self.inverse_eval(force_mN + self.inverse_in, self.k_force_inv))

    def deformation_targets(self, force_mN, out):
        """Fill out[s + 1] (s = -1, 0, +1) with the deformation that makes the load feel
        `force_mN` when the block's friction acts with direction s (see the module docstring)."""
        h = self.st[FRIC]
        s = -1
        while s <= 1:
            out[s + 1] = self.deformation_for(force_mN - h * s)
            s += 1
