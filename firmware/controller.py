"""The control step: sample, check, convert, control, limit, drive, record. One call per tick.

Called by a hard timer interrupt on a board, so it allocates nothing, uses integers only and
never raises: an exception inside it stops the motor and is recorded as a fault. Parameters live
in one preallocated array('i') (PARAMS gives names, defaults and the ranges that keep every
intermediate within +-2**30); the main loop changes them through App.set_param.
"""

from array import array

from firmware.pi_control import DUTY_MAX, GAIN_MAX, PI, slew
from firmware.portable import const
from firmware.safety import (
    FAULT_HOST_TIMEOUT,
    FAULT_RAIL_POT1,
    FAULT_RAIL_POT2,
    FAULT_STEP_EXCEPTION,
)
from firmware.sampler import NO_RAIL, RAIL_POT1

IDLE = const(0)
OPEN_LOOP = const(1)
POSITION = const(2)
FORCE = const(3)
MODE_NAMES = ("idle", "open_loop", "position", "force")

# Parameter indices (into Controller.p) and the table: name, default, min, max.
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
PARAMS = (
    ("kp_pos", 768, 0, GAIN_MAX),  # Q8 duty per um of position error
    ("ki_pos", 16, 0, GAIN_MAX),  # Q8 duty per um per step, into the Q8 integral
    ("kp_force", 2560, 0, GAIN_MAX),  # Q8 duty per um of deformation error
    ("ki_force", 8192, 0, GAIN_MAX),
    ("out_limit", 8000, 0, DUTY_MAX),  # |PI output| limit, duty
    ("int_limit", 6000, 0, DUTY_MAX),  # |integral| limit, duty
    ("slew", 500, 0, DUTY_MAX),  # max duty change per step (0 = unlimited)
    ("host_timeout_ms", 1000, 0, 600000),  # host silence that stops the motor (0 = off)
    ("rail_reads", 4, 1, 1000),  # consecutive reads at a rail that make a fault
    ("rail_margin", 0, 0, 255),  # codes from the rail that count as "at the rail"
    ("stroke_min_um", 500, -65535, 65535),  # soft stroke limits on D1* and D2
    ("stroke_max_um", 59500, -65535, 65535),
    ("slow_zone_um", 5000, 1, 65535),  # |duty| toward a limit is capped, falling to 0 over this
    ("defl_rate_um", 2, 0, 65535),  # force mode: the deformation setpoint moves at most this per step (0 = jump)
)
_T_MASK = const(0x3FFFFFFF)


class Controller:
    def __init__(self, sampler, measurement, motor, ring, safety, loop_hz):
        self.sampler = sampler
        self.meas = measurement  # None without a usable calibration: raw readings only
        self.motor = motor
        self.ring = ring
        self.safety = safety
        self.pi = PI()
        self.p = array("i", [d for _, d, _, _ in PARAMS])
        self.period_us = 1000000 // loop_hz
        self.mode = IDLE
        self.target = 0  # duty (open_loop), um (position) or mN (force)
        # Force mode: [deformation um for friction edge -1, 0, +1, force target mN]. Written
        # whole into the spare and swapped in by one assignment, so the step never sees a mix.
        self.force_set = array("i", [0, 0, 0, 0])
        self._spare_set = array("i", [0, 0, 0, 0])
        self.fdir = 0  # force mode: which side of the friction band the spring must work from
        self.defl_sp = 0  # force mode: the deformation setpoint, um, ramping toward its target
        self.duty = 0
        self.t_us = 0
        self.steps = 0
        self.apply_params()

    def apply_params(self):
        """Push the parameters that live in other objects (call after changing self.p)."""
        self.safety.set_timeout_ms(self.p[P_HOST_TIMEOUT_MS])
        self.sampler.rail_reads = self.p[P_RAIL_READS]
        self.sampler.rail_margin = self.p[P_RAIL_MARGIN]

    def step(self, _timer=None):
        """The timer callback. Never raises: a failure stops the motor and latches a fault."""
        try:
            self._step()
        except Exception as exc:  # a hard IRQ cannot propagate it, so record and stop
            self.mode = IDLE
            self.duty = 0
            self.safety.exc = exc
            self.safety.trip(FAULT_STEP_EXCEPTION)
            try:
                self.motor.off()
            except Exception:
                pass

    def _step(self):
        s = self.sampler
        sf = self.safety
        p = self.p
        s.sample()
        if s.rail != NO_RAIL and not (sf.faults & (FAULT_RAIL_POT1 | FAULT_RAIL_POT2)):
            sf.rail_value = s.rail_value
            sf.trip(FAULT_RAIL_POT1 if s.rail == RAIL_POT1 else FAULT_RAIL_POT2)
        mode = self.mode
        if mode != IDLE and sf.tick():
            sf.trip(FAULT_HOST_TIMEOUT)
        m = self.meas
        if m is not None:
            m.update(s.raw1, s.raw2)
        if sf.faults:
            mode = IDLE
            self.mode = IDLE
        if mode == IDLE:
            duty = 0
        else:
            if mode == OPEN_LOOP:
                cmd = self.target
            elif mode == POSITION:
                cmd = self.pi.update(self.target - m.d2, p[P_KP_POS], p[P_KI_POS], p[P_OUT_LIMIT], p[P_INT_LIMIT])
            else:
                # With the block's friction h calibrated, the load's force only moves once the
                # spring force leaves a band 2h wide around it: to lower it the spring works from
                # the band's lower edge (target - h), to raise it from the upper one. Once the
                # load-force estimate is within h/16 of the target the spring parks in the
                # middle of the band (the target itself), h away from both edges, so that noise
                # can no longer slide the block and the choice cannot chatter.
                fs = self.force_set
                e = fs[3] - m.force
                tol = m.fric >> 4
                if e < -tol:
                    self.fdir = 1
                elif e > tol:
                    self.fdir = -1
                else:
                    self.fdir = 0
                # The setpoint ramps (defl_rate_um per step, ~25 N/s by default) so that the block
                # slides quasi-statically: the friction model holds for a block that comes to
                # rest under a slowly changing force, not for one that hits its load at speed.
                sp = slew(self.defl_sp, fs[self.fdir + 1], p[P_DEFL_RATE])
                self.defl_sp = sp
                cmd = self.pi.update(sp - m.defl, p[P_KP_FORCE], p[P_KI_FORCE], p[P_OUT_LIMIT], p[P_INT_LIMIT])
            if m is not None:
                cmd = self._stroke_limit(cmd, m.d1, m.d2)
            duty = slew(self.duty, cmd, p[P_SLEW])
            if mode != OPEN_LOOP:
                self.pi.applied(duty)
        self.motor.set(duty)
        self.duty = duty
        self.steps += 1
        self.t_us = (self.t_us + self.period_us) & _T_MASK
        r = self.ring
        if r.due():
            if m is None:
                r.write_record(self.t_us, s.raw1, s.raw2, s.raw_ref, 0, 0, 0, 0, self.target, duty, mode, sf.faults)
            else:
                r.write_record(
                    self.t_us, s.raw1, s.raw2, s.raw_ref, m.d1, m.d2, m.defl, m.force, self.target, duty, mode, sf.faults
                )

    def set_force_target(self, force_mN):
        """Outside the interrupt: the deformation targets of a new force target (through the
        calibration's d(F0) and friction), then one swap of the whole set."""
        spare = self._spare_set
        self.meas.deformation_targets(force_mN, spare)
        spare[3] = force_mN
        self._spare_set = self.force_set
        self.force_set = spare
        self.target = force_mN

    def _stroke_limit(self, cmd, d1, d2):
        """Soft stroke limits: toward an end, |duty| is capped at DUTY_MAX * room / slow_zone_um,
        so a fast approach slows over the last slow_zone_um and stops at the limit, while a
        smaller command (a loop holding a target inside the zone) passes unchanged."""
        p = self.p
        if cmd > 0:
            room = p[P_STROKE_MAX] - (d1 if d1 > d2 else d2)
        elif cmd < 0:
            room = (d1 if d1 < d2 else d2) - p[P_STROKE_MIN]
        else:
            return 0
        if room <= 0:
            return 0
        zone = p[P_SLOW_ZONE]
        if room < zone:
            cap = (DUTY_MAX * room) // zone  # room < zone <= 65535: < 2**30
            if cmd > cap:
                return cap
            if cmd < -cap:
                return -cap
        return cmd
