"""The simulated LSEA: DC motor, lead screw, preloaded spring pair, output block, load and sensors.

Units inside: positions in mm, speeds in mm/s, forces in N, masses in kg, time in s.
Mechanics (one degree of freedom each for the nut and the block):
- Motor and screw: the rotor inertia seen at the nut is J * G**2 with G = gear * 2 pi / lead
  (rad per metre of nut travel). The motor's electrical time constant (L/R, ~0.1 ms) is far below
  a tick, so the current is quasi-static, i = (V - ke * omega) / R, and the drive force on the
  nut is eta * kt * G * i. Its back-EMF part is a viscous term, integrated implicitly.
- Springs: the nut drives the block through two preloaded springs. While the preload keeps both
  in contact their net force is F(d) = k1 d + k2 d|d| of the deformation d = nut - block (the paper
  section 4). Beyond d_release = preload_n / (k1 / 2) one spring has lost its preload and lifts
  off: from there only the other spring acts and the slope halves. Hard contact at
  |d| = cavity_mm (an inelastic constraint).
- Block: mass on a slider with Coulomb and viscous friction (stick when the net force cannot
  overcome Coulomb friction), hard end stops at the stroke ends.
- Load: none, a constant force, or a force gauge pulled through a fibre: a spring that acts only
  in tension. On the "high" side (default) the gauge sits toward 60 mm and the fibre is taut when
  the block is below the anchor, as in the paper's section 4 where pulling the block leftward gives
  negative actuator forces; on the "low" side it sits toward 0 mm, taut above the anchor, and the
  actuator's forces against it are positive.
Integration: semi-implicit (symplectic) Euler with enough sub-steps per call that omega * h
stays below `max_omega_dt` for the stiffest spring in play; contacts are position projections.
Sensors: see potentiometer.py (pots) and the adc_* methods below (ADC model).
"""

import math

from boards.sim import noise
from boards.sim.potentiometer import Potentiometer

CHANNELS = ("pot1", "pot2", "reference", "gauge")
REFERENCE_TARGETS = ("pot1", "pot2", "nut", "block", "gauge")
_NOISE_MASK = noise.TABLE_SIZE - 1


class Actuator:
    def __init__(self, params, seed):
        p = params
        self.params = p
        rng = noise.Rng(seed)
        self._noise = noise.normal_table(rng)
        self._adc_state = rng.next_u32() | 1
        bits = int(p.get("adc_bits", 12))
        if not 8 <= bits <= 16:
            raise ValueError("adc_bits must be 8..16")
        self.adc_bits = bits
        self.full_code = (1 << bits) - 1
        # MicroPython's read_u16 left-aligns the code and repeats its top bits below it.
        self._lshift = 16 - bits
        self._rshift = 2 * bits - 16

        m = p["motor"]
        s = p["screw"]
        self.R = float(m["resistance_ohm"])
        self.ke = float(m["ke_v_s_per_rad"])
        self.kt = float(m["kt_nm_per_a"])
        self.G = float(m.get("gear_ratio", 1.0)) * 2.0 * math.pi / (float(s["lead_mm"]) / 1000.0)
        self.eta = float(s["efficiency"])
        self.M1 = float(s["nut_mass_kg"]) + float(m["rotor_inertia_kg_m2"]) * self.G * self.G
        self.b_motor = self.eta * self.kt * self.ke * self.G * self.G / self.R  # N s/m at the nut

        sp = p["springs"]
        self.k1 = float(sp["k1_n_per_mm"])
        self.k2 = float(sp["k2_n_per_mm2"])
        self.cavity = float(sp["cavity_mm"])
        self.d_release = float(sp["preload_n"]) / (self.k1 / 2.0)
        r = self.d_release
        self.f_release = self.k1 * r + self.k2 * r * r
        self.k_after = (self.k1 + 2.0 * self.k2 * r) / 2.0
        self.c_spring = float(sp["damping_n_s_per_m"])

        b = p["block"]
        self.m2 = float(b["mass_kg"])
        self.f_coulomb = float(b["coulomb_n"])
        self.c_slider = float(b["viscous_n_s_per_m"])
        self.lo = float(b["stroke_mm"][0])
        self.hi = float(b["stroke_mm"][1])
        self.max_omega_dt = float(p.get("integration", {}).get("max_omega_dt", 0.3))

        self.pots = (Potentiometer(p["pots"]["pot1"]), Potentiometer(p["pots"]["pot2"]))
        r = p["reference"]
        self.ref_zero = float(r["zero_mm"])
        self.ref_span = float(r["span_mm"])
        self.set_reference(r.get("mounted_on", "pot2"))
        g = p["gauge"]
        self.gauge = g
        # The gauge zero drifts linearly at a seed-chosen rate up to drift_n_per_min, bounded.
        self.gauge_drift_rate = float(g["drift_n_per_min"]) / 60.0 * (2.0 * rng.uniform() - 1.0)
        self.gauge_drift_max = float(g["drift_max_n"])

        noise_lsb = (p["pots"]["pot1"]["noise_lsb"], p["pots"]["pot2"]["noise_lsb"],
                     r["noise_lsb"], g["noise_lsb"])
        self._sigma_q8 = [int(float(v) * 256.0 + 0.5) for v in noise_lsb]
        self._base_q8 = [0, 0, 0, 0]
        self._fault = [-1, -1, -1, -1]  # forced code per channel, -1 = healthy

        self.volts = 0.0
        self.time_s = 0.0
        self._dt_cached = -1.0
        self._n_sub = 1
        self.set_load("none")
        self.place(float(p.get("start", {}).get("block_mm", 30.0)))

    # --- configuration -------------------------------------------------------------------

    def place(self, block_mm, deformation_mm=0.0):
        """Put the block (and the nut at the given deformation) somewhere, at rest."""
        self.block_mm = float(block_mm)
        self.nut_mm = self.block_mm + float(deformation_mm)
        self.nut_speed_mm_s = 0.0
        self.block_speed_mm_s = 0.0
        self._update_outputs()

    def set_load(self, kind="none", anchor_mm=None, stiffness_n_per_mm=None, force_n=0.0, side="high"):
        """External load on the block: "none"; "gauge" (fibre to a force gauge on `side` "high",
        taut when the block is below anchor_mm, or "low", taut above it); "constant" (force_n on
        the block, + toward 60 mm)."""
        if kind not in ("none", "gauge", "constant"):
            raise ValueError("load kind must be none, gauge or constant")
        if side not in ("high", "low"):
            raise ValueError("gauge side must be high or low")
        self.gauge_side = 1 if side == "high" else -1
        g = self.gauge
        self.load_kind = kind
        self.anchor_mm = float(g["anchor_mm"] if anchor_mm is None else anchor_mm)
        self.k_gauge = float(g["stiffness_n_per_mm"] if stiffness_n_per_mm is None
                             else stiffness_n_per_mm)
        self.load_force_n = float(force_n)
        self._dt_cached = -1.0  # stiffness changed: recompute the sub-step count
        if hasattr(self, "block_mm"):
            self._update_outputs()

    def set_reference(self, target):
        """Where the calibration rig's reference sensor is mounted: in parallel with "pot1" or
        "pot2" (it then measures that pot's wiper travel, as on the paper's bench rig, so the
        mounting error stays for calibration 2), or on the true "nut" / "block" position; or
        "gauge": the force gauge's analog output wired to the reference input instead (the force
        step's gauge channel), read as the gauge channel's signal."""
        if target not in REFERENCE_TARGETS:
            raise ValueError("reference target must be one of %s" % (REFERENCE_TARGETS,))
        self.reference_on = target
        if hasattr(self, "block_mm"):
            self._update_outputs()

    def inject_fault(self, channel, kind="wiper_lift", rail=None):
        """Make a channel misbehave. "wiper_lift": the wiper leaves the track and the input is
        pulled to a rail ("high" or "low"; default from the pot's wiper_lift_rail)."""
        i = CHANNELS.index(channel)
        if kind != "wiper_lift":
            raise ValueError("unknown fault %r" % kind)
        if rail is None:
            rail = self.params["pots"].get(channel, {}).get("wiper_lift_rail", "high")
        self._fault[i] = self.full_code if rail == "high" else 0

    def clear_faults(self):
        self._fault = [-1, -1, -1, -1]

    def set_motor_voltage(self, volts):
        self.volts = float(volts)

    # --- physics -------------------------------------------------------------------------

    def spring_force(self, d_mm):
        """Net spring force (N) on the block for deformation d = nut - block (mm)."""
        if d_mm > self.d_release:
            return self.f_release + self.k_after * (d_mm - self.d_release)
        if d_mm < -self.d_release:
            return -self.f_release + self.k_after * (d_mm + self.d_release)
        return self.k1 * d_mm + self.k2 * d_mm * abs(d_mm)

    def _substeps(self, dt):
        if dt != self._dt_cached:
            k = self.k1 + 2.0 * self.k2 * self.cavity
            if self.load_kind == "gauge":
                k += self.k_gauge
            omega = math.sqrt(1000.0 * k / self.m2)
            self._n_sub = int(dt * omega / self.max_omega_dt) + 1
            self._dt_cached = dt
        return self._n_sub

    def advance(self, dt_s):
        """Advance the world by dt_s seconds at the present motor voltage."""
        n = self._substeps(dt_s)
        h = dt_s / n
        M1 = self.M1
        m2 = self.m2
        tot = M1 + m2
        f_drive = self.eta * self.kt * self.G * self.volts / self.R
        damp1 = 1.0 + h * self.b_motor / M1
        damp2 = 1.0 + h * self.c_slider / m2
        dv_c = h * 1000.0 * self.f_coulomb / m2
        a1 = h * 1000.0 / M1
        a2 = h * 1000.0 / m2
        cav = self.cavity
        lo = self.lo
        hi = self.hi
        x1 = self.nut_mm
        x2 = self.block_mm
        v1 = self.nut_speed_mm_s
        v2 = self.block_speed_mm_s
        i = 0
        while i < n:
            d = x1 - x2
            fs = self.spring_force(d) + self.c_spring * (v1 - v2) / 1000.0
            fe = self._external(x2)
            v1 = (v1 + a1 * (f_drive - fs)) / damp1
            v2 = (v2 + a2 * (fs + fe)) / damp2
            if v2 > dv_c:
                v2 -= dv_c
            elif v2 < -dv_c:
                v2 += dv_c
            else:
                v2 = 0.0
            x1 += h * v1
            x2 += h * v2
            # Cavity hard contact: an inelastic collision of nut and block.
            d = x1 - x2
            if d > cav or d < -cav:
                lim = cav if d > 0 else -cav
                excess = d - lim
                x1 -= excess * m2 / tot
                x2 += excess * M1 / tot
                if (v1 - v2) * excess > 0:
                    v1 = v2 = (M1 * v1 + m2 * v2) / tot
            # End stops hold the block; the nut then stops at the cavity wall.
            if x2 < lo:
                x2 = lo
                if v2 < 0:
                    v2 = 0.0
            elif x2 > hi:
                x2 = hi
                if v2 > 0:
                    v2 = 0.0
            if x1 - x2 > cav:
                x1 = x2 + cav
                if v1 > v2:
                    v1 = v2
            elif x1 - x2 < -cav:
                x1 = x2 - cav
                if v1 < v2:
                    v1 = v2
            i += 1
        self.nut_mm = x1
        self.block_mm = x2
        self.nut_speed_mm_s = v1
        self.block_speed_mm_s = v2
        self.time_s += dt_s
        self._update_outputs()

    def _external(self, x2):
        if self.load_kind == "gauge":
            stretch = (self.anchor_mm - x2) * self.gauge_side
            if stretch > 0:
                return self.k_gauge * stretch * self.gauge_side
            return 0.0
        if self.load_kind == "constant":
            return self.load_force_n
        return 0.0

    def _update_outputs(self):
        d = self.nut_mm - self.block_mm
        self.deformation_mm = d
        self.spring_force_n = self.spring_force(d)
        self.external_force_n = self._external(self.block_mm)
        omega = self.nut_speed_mm_s / 1000.0 * self.G
        self.motor_current_a = (self.volts - self.ke * omega) / self.R
        self.gauge_tension_n = self.external_force_n * self.gauge_side if self.load_kind == "gauge" else 0.0
        drift = self.gauge_drift_rate * self.time_s
        if drift > self.gauge_drift_max:
            drift = self.gauge_drift_max
        elif drift < -self.gauge_drift_max:
            drift = -self.gauge_drift_max
        self.gauge_reading_n = self.gauge_tension_n + drift
        full = self.full_code * 256.0
        self._base_q8[0] = _q8(self.pots[0].fraction(self.nut_mm), full)
        self._base_q8[1] = _q8(self.pots[1].fraction(self.block_mm), full)
        g = self.gauge
        self._base_q8[3] = _q8(float(g["zero_fraction"]) + self.gauge_reading_n
                               / float(g["n_per_fraction"]), full)
        if self.reference_on == "gauge":
            self.reference_mm = float("nan")
            self._base_q8[2] = self._base_q8[3]
        else:
            self.reference_mm = self._reference_position()
            self._base_q8[2] = _q8((self.reference_mm - self.ref_zero) / self.ref_span, full)

    def _reference_position(self):
        t = self.reference_on
        if t == "pot1":
            return self.pots[0].wiper_mm(self.nut_mm)
        if t == "pot2":
            return self.pots[1].wiper_mm(self.block_mm)
        if t == "nut":
            return self.nut_mm
        return self.block_mm

    # --- ADC -----------------------------------------------------------------------------

    def channel_index(self, name):
        return CHANNELS.index(name)

    def adc_u16(self, name):
        """What ADC.read_u16() returns for channel `name` on this board (noisy, quantised)."""
        return self.read_u16_index(CHANNELS.index(name))

    def adc_code(self, name):
        """One noisy reading in the board's native bits (0 .. 2**adc_bits - 1)."""
        return self.read_u16_index(CHANNELS.index(name)) >> self._lshift

    def read_u16_index(self, i):
        """Allocation-free (small ints only): safe inside a heap_lock()ed firmware step."""
        code = self._fault[i]
        if code < 0:
            x = self._adc_state
            x ^= (x << 13) & 0xFFFFFFFF
            x ^= x >> 17
            x ^= (x << 5) & 0xFFFFFFFF
            self._adc_state = x
            code = (self._base_q8[i] + ((self._noise[x & _NOISE_MASK] * self._sigma_q8[i]) >> 8)) >> 8
            if code < 0:
                code = 0
            elif code > self.full_code:
                code = self.full_code
        return (code << self._lshift) | (code >> self._rshift)

    def true_code(self, name):
        """The noise-free code a channel would read now (for tests and calibration checks)."""
        return self._base_q8[CHANNELS.index(name)] >> 8

    def code_value(self, name):
        """The channel's noise-free input in codes, unrounded (1/256 code): what its reads average
        to, and what a table of code against position must pair with the position. The rounded
        true_code is up to half a code (7-10 um of a pot) off it."""
        return (self._base_q8[CHANNELS.index(name)] - 128) / 256.0


def _q8(fraction, full_q8):
    """Fraction of full scale -> code in Q8 with +0.5 LSB so that >> 8 rounds. An input beyond
    a rail saturates there (read_u16_index clamps); the clamp here only bounds the integer."""
    if fraction < -1.0:
        fraction = -1.0
    elif fraction > 2.0:
        fraction = 2.0
    return int(fraction * full_q8 + 128.0)
