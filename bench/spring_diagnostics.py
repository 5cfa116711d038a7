"""Diagnostic spring forces for the offline force benches (bench_force_steps_offline.py --spring).

The firmware's load estimate is a play operator of width h on F0(d), the spring force of the
measured deformation, low-passed over 64 steps (firmware/measurement.py). These replace the
force the play operator is fed, to ask how much of the force steps' error is the estimate's
input (its noise and its lag) rather than the play model or the loop:

  true      the simulator's true spring force (no bench has it): the best input there could be.
  observer  a model-based observer of the nut, driven by the motor voltage the simulator applies,
            with the board's TRUE motor and screw constants (a firmware would have to identify
            them): M x'' = c V - F0(x - D2f) - b x', corrected by the measured D1* with fixed
            gains. It follows the spring without the 64-step average's lag and with far less of
            the pots' noise, as long as its constants are right (`drive_scale` scales c to show
            how much an error in them costs).

Both are patched onto firmware.measurement.Measurement from the bench process (the firmware is
not changed); pair them with --filter-shift 0 (the estimate's own average off) to feed the play
operator the diagnostic force directly.
"""

import contextlib
import math

OBSERVER_GAINS = (0.01, 0.00005)  # position and velocity corrections per step (found by trial on one board)
D2_FILTER = 0.0625  # the block's measured position low-passed over ~16 steps (it barely moves while it sticks)


@contextlib.contextmanager
def feeding(kind, drive_scale=1.0, bias_hz=0.0):
    """Within the block, Measurements feed their play operator `kind`'s spring force."""
    import boards.sim.machine as sim
    import firmware.measurement as measurement

    original = measurement.Measurement._load_force

    def true_spring(self, f):
        return original(self, int(sim.world().spring_force_n * 1000.0))

    def observed_spring(self, f):
        return original(self, _Observer.of(self, sim.world(), drive_scale, bias_hz).step(self))

    measurement.Measurement._load_force = true_spring if kind == "true" else observed_spring
    try:
        yield
    finally:
        measurement.Measurement._load_force = original


class _Observer:
    """A second-order model of the nut against the spring, in the firmware's own millimetres."""

    @classmethod
    def of(cls, meas, world, drive_scale, bias_hz):
        obs = getattr(meas, "_diagnostic_observer", None)
        if obs is None:
            obs = meas._diagnostic_observer = cls(meas, world, drive_scale, bias_hz)
        return obs

    def __init__(self, meas, world, drive_scale, bias_hz):
        self.world = world
        self.bias_hz = bias_hz
        self.drive_n_per_v = drive_scale * world.eta * world.kt * world.G / world.R
        self.damping = world.b_motor + world.c_spring  # N s/m
        self.mass = world.M1  # kg: the nut and the rotor's inertia seen through the screw
        self.x1 = meas.d1 / 1000.0
        self.v1 = 0.0
        self.bias = 0.0  # N: what the model's drive force misses (its constants' error, friction)
        self.x2 = meas.d2 / 1000.0

    def spring_mN(self, meas):
        """The spring force of the observed deformation, mN (F0 of the firmware's calibration)."""
        from firmware.measurement import F_IN

        return int(meas.force_eval(int(round((self.x1 - self.x2) * 1000.0)) + meas.st[F_IN], meas.k_force))

    def step(self, meas, dt=0.001):  # one loop step at 1 kHz (the bench's rate unless --loop-hz)
        self.x2 += (meas.d2 / 1000.0 - self.x2) * D2_FILTER
        spring_n = self.spring_mN(meas) / 1000.0
        accel = 1000.0 * (self.drive_n_per_v * self.world.volts + self.bias - spring_n
                          - self.damping * self.v1 / 1000.0) / self.mass
        self.v1 += accel * dt
        self.x1 += self.v1 * dt
        error = meas.d1 / 1000.0 - self.x1
        self.x1 += OBSERVER_GAINS[0] * error
        self.v1 += OBSERVER_GAINS[1] * error / dt
        if self.bias_hz:
            self.bias += self._bias_gain(meas, dt) * dt * error
        return self.spring_mN(meas)

    def _bias_gain(self, meas, dt):
        """N per mm s: the bias's correction that puts its pole near -2 pi bias_hz. With the nut's
        corrections as continuous gains l1 = g0 / dt, l2 = g1 / dt^2, the error's characteristic
        polynomial is s^3 + (l1 + b/M) s^2 + (l1 b/M + 1000 k/M + l2) s + 1000 l3 / M, k the
        calibration's local stiffness (N/mm)."""
        from firmware.measurement import F_IN

        l1, l2 = OBSERVER_GAINS[0] / dt, OBSERVER_GAINS[1] / (dt * dt)
        d = int(round((self.x1 - self.x2) * 1000.0)) + meas.st[F_IN]
        k = abs(meas.force_eval(d + 50, meas.k_force) - meas.force_eval(d - 50, meas.k_force)) / 100.0
        linear = l1 * self.damping / self.mass + 1000.0 * k / self.mass + l2
        return 2 * math.pi * self.bias_hz * linear * self.mass / 1000.0
