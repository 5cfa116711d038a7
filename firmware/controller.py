"""The control step: sample, check, convert, control, limit, drive, record. One call per tick.

Called by a hard timer interrupt on a board, so it allocates nothing, uses integers only and
never raises: an exception inside it stops the motor and is recorded as a fault. Parameters live
in one preallocated array('i') (protocol.PARAMS gives names, defaults and the ranges that keep
every intermediate within +-2**30); the main loop changes them through App.set_param.

The step is viper code over int32 blocks (this one's `Controller.st`, and the sampler's,
safety's, measurement's and PI's): machine-word arithmetic and single loads and stores, so that
it fits a 1 kHz period on a Cortex-M0 with room to spare (bench/bench_mcu.py, docs/firmware.md).
Every counter in it wraps or saturates inside 31 bits, so it runs for any uptime. It times
itself: the longest step since boot and the overruns (a step that started at least half a period
late, or ran for a whole period) are in status().

The step's choices carry a tag ([force-band], [pos-park], ...) and one line; why each was made,
with the measurements behind it, is in docs/firmware.md, "The step's choices", under that tag.
"""

from array import array

from firmware.pi_control import PI
from firmware.portable import TICK_US, const, ptr32, ticks_us, word_property, zeros
from firmware.protocol import PARAMS
from firmware.safety import FAULT_STEP_EXCEPTION

try:
    import micropython  # @micropython.viper is resolved by MicroPython's compiler
except ImportError:  # CPython
    from firmware import portable as micropython

# Modes, numbered as protocol.MODES names them
IDLE = const(0)
OPEN_LOOP = const(1)
POSITION = const(2)
FORCE = const(3)

# Parameter indices (into Controller.p), in the order of protocol.PARAMS
P_KP_POS = const(0)
P_KI_POS = const(1)
P_KP_FORCE = const(2)
P_KI_FORCE = const(3)
P_OUT_LIMIT = const(4)
P_INT_LIMIT = const(5)
P_SLEW = const(6)
P_HOST_TIMEOUT_MS = const(7)
P_RAIL_READS = const(8)
P_RAIL_MARGIN = const(9)
P_STROKE_MIN = const(10)
P_STROKE_MAX = const(11)
P_SLOW_ZONE = const(12)
P_DEFL_RATE = const(13)
P_STOP_MARGIN = const(14)
P_POS_DEADBAND = const(15)
_MASK = const(0x3FFFFFFF)  # [wrap] t_us, steps and tick differences wrap at 2**30

# [sign-fix] (docs/firmware.md, Viper idioms): a word that may be negative is read as ((v + _B29) & _M30) - _B29
_B29 = const(536870912)
_M30 = const(1073741823)

# [copied-constants] (docs/firmware.md, Viper idioms): what the step uses of the other modules.
_DUTY_MAX = const(10000)  # pi_control.DUTY_MAX
_S_RAW1 = const(0)  # sampler.RAW1 ...
_S_RAW2 = const(1)
_S_RAW_REF = const(2)
_S_RAIL = const(3)
_S_RAIL_VALUE = const(4)
_NO_RAIL = const(0)  # sampler.NO_RAIL
_RAIL_POT1 = const(1)  # sampler.RAIL_POT1
_F_FAULTS = const(0)  # safety.FAULTS
_FAULT_RAIL_POT1 = const(1)  # safety.FAULT_RAIL_POT1 ...
_FAULT_RAIL_POT2 = const(2)
_FAULT_HOST_TIMEOUT = const(4)
_M_D1 = const(0)  # measurement.D1 ...
_M_D2 = const(1)
_M_DEFL = const(2)
_M_FORCE = const(3)
_M_FRIC = const(8)
_M_FF_DUTY = const(15)  # measurement.FF_DUTY
_M_FS_SHIFT = const(18)  # measurement.FS_SHIFT
_PARK_STEPS = const(50)  # position mode: steps inside the deadband before the block counts as parked
_DEFL_LEAD = const(60)  # force mode: um the deformation setpoint may lead the measured deformation
_HOLD_SHIFT = const(1)  # force mode: the PI gains halved while the spring holds its goal (within _DEFL_LEAD)

# Controller.st
MODE = const(0)
TARGET = const(1)  # duty (open_loop), um (position) or mN (force)
DUTY = const(2)
T_US = const(3)  # loop time: steps x period, mod 2**30
STEPS = const(4)  # steps since boot, mod 2**30 (12.4 days at 1 kHz)
FDIR = const(5)  # force mode: which side of the friction band the spring must work from
DEFL_SP = const(6)  # force mode: the deformation setpoint, um, ramping toward its target
PERIOD = const(7)  # us
LAST_START = const(8)  # ticks_us (mod 2**30) at the start of the last step
TIMED = const(9)  # 1 once LAST_START holds a step of this timer run
STEP_US_MAX = const(10)  # the longest step since boot, us
OVERRUNS = const(11)  # steps that started >= 1.5 periods after the previous one or ran >= 1 period (+ TICK)
HAS_MEAS = const(12)  # 1 while a Measurement is set (an int test is 2 instructions, `if obj` ~1300)
LIM_LO = const(13)  # the soft stroke limits in force on D2, um (apply_params works them out)
LIM_HI = const(14)
EF = const(15)  # position mode: 16 x the error low-passed over ~16 steps, um (decides the friction feed-forward)
PARKED = const(16)  # position mode with feed-forward: steps inside the deadband, up to _PARK_STEPS (parked)
TICK = const(17)  # the step clock's resolution, us: a gap or a step is late only beyond what it can misread
SP_FRAC = const(18)  # force mode: the setpoint's move carried over, 1/16 um ([force-approach])
WORDS = const(19)

# the step's record for the telemetry ring, in the order of protocol.FIELDS
_R_T = const(0)
_R_RAW1 = const(1)
_R_RAW2 = const(2)
_R_REF = const(3)
_R_D1 = const(4)
_R_D2 = const(5)
_R_DEFL = const(6)
_R_FORCE = const(7)
_R_TARGET = const(8)
_R_DUTY = const(9)
_R_MODE = const(10)
_R_FAULTS = const(11)


class Controller:
    def __init__(self, sampler, measurement, motor, ring, safety, loop_hz):
        self.st = zeros(WORDS)
        self.sampler = sampler
        self.meas = measurement  # None without a usable calibration: raw readings only
        self.motor = motor
        self.ring = ring
        self.safety = safety
        self.pi = PI()
        self.p = array("i", [row[1] for row in PARAMS])
        self.st[PERIOD] = 1000000 // loop_hz
        self.st[TICK] = TICK_US  # 1000 on CircuitPython, whose step clock counts whole ms (portable.us_from_ms)
        self.rec = zeros(12)  # the step's telemetry record, handed to the ring
        self._ticks = ticks_us
        # Bound once here (binding allocates): viper code has no inline caches, so a method
        # call looks in the instance, misses, then searches the class (~500 instructions on a
        # Cortex-M0); a bound method kept on the instance is found by the first look.
        self._sample = sampler.sample
        self._tick = safety.tick
        self._pi_update = self.pi.update
        self._pi_applied = self.pi.applied
        self._motor_set = motor.set
        self._push = ring.push
        self._body = self._step
        # Force mode: [deformation um for friction edge -1, 0, +1, force target mN]. Written
        # whole into the spare and swapped in by one assignment, so the step never sees a mix.
        self.force_set = zeros(4)
        self._spare_set = zeros(4)
        self.end_stops = None  # [low_um, high_um] of the block's end stops in D2, from the calibration
        self.apply_params()

    # --- the block's fields, for the main loop, people and tests -----------------------------
    mode = word_property(MODE, True)
    target = word_property(TARGET, True)
    duty = word_property(DUTY, True)
    t_us = word_property(T_US, True)
    steps = word_property(STEPS, True)
    fdir = word_property(FDIR, True)
    defl_sp = word_property(DEFL_SP, True)
    period_us = word_property(PERIOD, True)
    step_us_max = word_property(STEP_US_MAX, True)
    overruns = word_property(OVERRUNS, True)

    @property
    def meas(self):
        return self._meas

    @meas.setter
    def meas(self, m):
        self._meas = m
        self._update = None if m is None else m.update  # bound once, as the others (below)
        self.st[HAS_MEAS] = 0 if m is None else 1

    def apply_params(self):
        """Push the parameters that live in other objects and work out the stroke limits in
        force (call after changing self.p or end_stops)."""
        p = self.p
        self.safety.set_timeout_ms(p[P_HOST_TIMEOUT_MS])
        self.sampler.rail_reads = p[P_RAIL_READS]
        self.sampler.rail_margin = p[P_RAIL_MARGIN]
        # The block's soft limits: the parameters, and with calibrated end stops never closer to
        # a stop than the margin (a negative margin, as calibration sweeps set, lets them reach it)
        lo, hi = p[P_STROKE_MIN], p[P_STROKE_MAX]
        stops = self.end_stops
        if stops is not None:
            lo = max(lo, stops[0] + p[P_STOP_MARGIN])
            hi = min(hi, stops[1] - p[P_STOP_MARGIN])
        self.st[LIM_LO] = lo
        self.st[LIM_HI] = hi

    @property
    def stroke_limits(self):
        """[low, high] um: the soft limits on D2 in force."""
        return [self.st[LIM_LO], self.st[LIM_HI]]

    def timer_started(self):
        """The loop timer (re)starts: the first step has no previous one to be late against."""
        self.st[TIMED] = 0

    # native, not viper: viper cannot bind `except ... as exc`; native still calls cheaper than bytecode
    @micropython.native
    def step(self, _timer):
        """The timer callback. Never raises: a failure stops the motor and latches a fault."""
        try:
            self._body()
        except Exception as exc:  # a hard IRQ cannot propagate it, so record and stop
            c = self.st
            c[MODE] = IDLE
            c[DUTY] = 0
            self.safety.exc = exc
            self.safety.trip(FAULT_STEP_EXCEPTION)
            try:
                self.motor.off()
            except Exception:
                pass

    @micropython.viper
    def _step(self):
        c = ptr32(self.st)
        t0 = int(self._ticks()) & _MASK
        period = c[PERIOD]
        if c[TIMED]:
            gap = (t0 - c[LAST_START]) & _MASK
            late = gap >= period + (period >> 1) + c[TICK]
        else:
            late = False
            c[TIMED] = 1
        c[LAST_START] = t0
        p = ptr32(self.p)
        self._sample()
        s = ptr32(self.sampler.st)
        sf = self.safety
        f = ptr32(sf.st)
        if s[_S_RAIL] != _NO_RAIL and not (f[_F_FAULTS] & (_FAULT_RAIL_POT1 | _FAULT_RAIL_POT2)):
            sf.rail_value = s[_S_RAIL_VALUE]
            sf.trip(_FAULT_RAIL_POT1 if s[_S_RAIL] == _RAIL_POT1 else _FAULT_RAIL_POT2)
        mode = c[MODE]
        # silence is counted in every mode (App.watch_host restores the parameters after it);
        # it stops the motor only when there is motion to stop
        if self._tick() and mode != IDLE:
            sf.trip(_FAULT_HOST_TIMEOUT)
        has_meas = c[HAS_MEAS]
        d1 = 0
        d2 = 0
        defl = 0
        force = 0
        fric = 0
        ffd = 0
        fsh = 0
        if has_meas:
            self._update(s[_S_RAW1], s[_S_RAW2])
            m = ptr32(self._meas.st)
            d1 = ((m[_M_D1] + _B29) & _M30) - _B29
            d2 = ((m[_M_D2] + _B29) & _M30) - _B29
            defl = ((m[_M_DEFL] + _B29) & _M30) - _B29
            force = ((m[_M_FORCE] + _B29) & _M30) - _B29
            fric = m[_M_FRIC]
            ffd = m[_M_FF_DUTY]
            fsh = m[_M_FS_SHIFT]
        if f[_F_FAULTS]:
            mode = IDLE
            c[MODE] = IDLE
        duty = 0
        if mode != IDLE:
            cmd = 0
            ff = 0
            if mode == OPEN_LOOP:
                cmd = ((c[TARGET] + _B29) & _M30) - _B29
            elif mode == POSITION:
                # [pos-friction] outside a deadband, the friction's duty added toward the target
                e = (((c[TARGET] + _B29) & _M30) - _B29) - d2
                # [pos-filter] the error low-passed over 16 steps, kept x16 with rounding
                acc = ((c[EF] + _B29) & _M30) - _B29
                acc = acc + e - ((acc + 8) >> 4)
                c[EF] = acc  # |acc| <= 16 * 131070 < 2**22
                ef = (acc + 8) >> 4
                ki = p[P_KI_POS]
                if ffd:
                    # [pos-park] parked after _PARK_STEPS inside the band, unparked beyond 3x it
                    db = p[P_POS_DEADBAND]
                    aef = ef if ef >= 0 else -ef
                    inside = c[PARKED]
                    if inside >= _PARK_STEPS:
                        if aef > 3 * db:
                            inside = 0
                    elif aef <= db:
                        inside = inside + 1
                    else:
                        inside = 0
                    c[PARKED] = inside
                    if inside >= _PARK_STEPS:
                        ki = 0
                    elif aef > db:
                        ff = ffd if ef > 0 else -ffd
                lim = p[P_OUT_LIMIT]
                cmd = int(self._pi_update(e, p[P_KP_POS], ki, lim, p[P_INT_LIMIT])) + ff
                if cmd > lim:
                    cmd = lim
                elif cmd < -lim:
                    cmd = -lim
            else:
                # [force-band] the spring driven to the band edge (target -+ h) from which the
                # load's force moves toward the target; within h/32 of it, parked at the target
                fs = ptr32(self.force_set)
                e = (((fs[3] + _B29) & _M30) - _B29) - force
                tol = fric >> 5
                fdir = 0
                if e < -tol:
                    fdir = 1
                elif e > tol:
                    fdir = -1
                c[FDIR] = fdir
                # [force-ramp] the setpoint ramps, and waits while it leads the spring by _DEFL_LEAD
                sp = ((c[DEFL_SP] + _B29) & _M30) - _B29
                goal = ((fs[fdir + 1] + _B29) & _M30) - _B29
                rate = p[P_DEFL_RATE]
                if rate <= 0:
                    sp = goal
                elif goal != sp:
                    togo = goal - sp
                    away = togo if togo > 0 else -togo
                    stp = rate
                    if away < rate << fsh:
                        # [force-approach] closing in, away / 2**fsh a step (the estimate's average): exponential, in 1/16 um,
                        # to the goal itself (a last jump of up to `rate` is 8 um at 250 Hz)
                        q = (away << 4) >> fsh
                        if q < 1:
                            q = 1
                        q = q + c[SP_FRAC]  # away < 2**18 (+-STROKE_CLAMP_UM): q < 2**23
                        stp = q >> 4
                        c[SP_FRAC] = q & 15
                    if stp > away:
                        stp = away
                    if togo > 0:
                        if sp < defl + _DEFL_LEAD:
                            sp = sp + stp
                    elif sp > defl - _DEFL_LEAD:
                        sp = sp - stp
                c[DEFL_SP] = sp
                # [force-hold] half the gains while holding the goal (the integral is in duty:
                # changing ki does not move the output)
                kp = p[P_KP_FORCE]
                ki = p[P_KI_FORCE]
                err = sp - defl
                if sp == goal and err < _DEFL_LEAD and err > -_DEFL_LEAD:
                    kp = kp >> _HOLD_SHIFT
                    ki = ki >> _HOLD_SHIFT
                cmd = int(self._pi_update(err, kp, ki, p[P_OUT_LIMIT], p[P_INT_LIMIT]))
            if has_meas:
                # [stroke-cap] toward a soft stroke limit |duty| <= DUTY_MAX * room / slow_zone_um
                room = 1
                if cmd > 0:
                    room = (((c[LIM_HI] + _B29) & _M30) - _B29) - d2
                elif cmd < 0:
                    room = d2 - (((c[LIM_LO] + _B29) & _M30) - _B29)
                if room <= 0:
                    cmd = 0
                elif room < p[P_SLOW_ZONE]:
                    cap = (_DUTY_MAX * room) // p[P_SLOW_ZONE]  # room < zone <= 65535: < 2**30
                    if cmd > cap:
                        cmd = cap
                    elif cmd < -cap:
                        cmd = -cap
            # slew: the duty moves at most `slew` per step toward the command (0 = no limit)
            prev = ((c[DUTY] + _B29) & _M30) - _B29
            rate = p[P_SLEW]
            duty = cmd
            if rate > 0:
                if cmd > prev + rate:
                    duty = prev + rate
                elif cmd < prev - rate:
                    duty = prev - rate
            if mode != OPEN_LOOP:
                self._pi_applied(duty - ff)  # what reached the motor of the PI's own output
        self._motor_set(duty)
        c[DUTY] = duty
        n = c[STEPS]
        c[STEPS] = 0 if n == _MASK else n + 1
        t = c[T_US]
        if t > _MASK - period:  # [wrap] t + period would reach 2**30: wrap without forming it
            t = t - (_MASK - period) - 1
        else:
            t = t + period
        c[T_US] = t
        r = ptr32(self.rec)
        r[_R_T] = t
        r[_R_RAW1] = s[_S_RAW1]
        r[_R_RAW2] = s[_S_RAW2]
        r[_R_REF] = s[_S_RAW_REF]
        r[_R_D1] = d1
        r[_R_D2] = d2
        r[_R_DEFL] = defl
        r[_R_FORCE] = force
        r[_R_TARGET] = c[TARGET]
        r[_R_DUTY] = duty
        r[_R_MODE] = mode
        r[_R_FAULTS] = f[_F_FAULTS]
        self._push(self.rec)
        dt = (int(self._ticks()) - t0) & _MASK
        if dt > c[STEP_US_MAX]:
            c[STEP_US_MAX] = dt
        if (late or dt >= period + c[TICK]) and c[OVERRUNS] < _MASK:
            c[OVERRUNS] = c[OVERRUNS] + 1

    def set_force_target(self, force_mN):
        """Outside the interrupt: the deformation targets of a new force target (through the
        calibration's d(F0) and friction), then one swap of the whole set."""
        spare = self._spare_set
        self.meas.deformation_targets(force_mN, spare)
        spare[3] = force_mN
        self._spare_set = self.force_set
        self.force_set = spare
        self.st[TARGET] = force_mN
