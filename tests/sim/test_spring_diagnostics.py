"""bench/spring_diagnostics.py: the offline bench's --spring inputs do what docs/robustness.md says."""

import math
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, os.path.join(ROOT, "bench"))

import offline_force_rig  # noqa: E402
import spring_diagnostics  # noqa: E402


def test_observer_follows_the_spring_far_closer_than_the_measured_deformation(tmp_path):
    """A 5 N force step on boards/sim.json with the play operator fed the observer: per step after
    the first 0.2 s (the observer starts at rest while the nut already moves), its spring force and
    F0 of the measured deformation against the true spring force (mN rms: about 40 and 210)."""
    import boards.sim.machine as sim
    from firmware.measurement import F_IN
    from tests.sim import force_cases

    board = os.path.join(ROOT, "boards", "sim.json")
    cal = offline_force_rig.exact_calibration(board, str(tmp_path / "exact.json"))
    observed, measured = [], []
    with spring_diagnostics.feeding("observer"):
        app, world, _sign = force_cases._hooked_on_side(cal, "low", 45000, 200, board)
        app.set_mode("force")
        app.set_target(5000)
        meas = app.ctrl.meas
        for k in range(1500):
            sim.run_ticks(1)
            app.heartbeat()
            if k < 200:
                continue
            true_mN = world.spring_force_n * 1000.0
            obs = meas._diagnostic_observer
            observed.append(obs.spring_mN(meas) - true_mN)
            measured.append(meas.force_eval(meas.defl + meas.st[F_IN], meas.k_force) - true_mN)
        app.shutdown()
    rms_observed, rms_measured = (math.sqrt(sum(e * e for e in v) / len(v)) for v in (observed, measured))
    assert rms_observed < rms_measured / 3, (rms_observed, rms_measured)
