"""The offline force rig (bench/offline_force_rig.py) replays a run's force step on the ladder that
run went up, not boards/sim.json's: a drawn motor's step shrinks (a strong motor) and its top
follows the force range, and a refit on 625 duty levels to 16 N fitted another F0 than the run's
(seed 202611282106: a fifth-order polynomial, 0.5 N off, where the run's ladder gives a table)."""

import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), "bench"))

import offline_force_rig  # noqa: E402


def test_the_refit_climbs_the_runs_own_ladder_on_each_side(tmp_path):
    run = tmp_path / "run-7"
    run.mkdir()
    rows = ["d_mm,force_n,s,loading,duty"]
    for duty, loading in ((-396.8, 1), (-793.7, 1), (-1190.5, 1), (-793.7, 0), (-396.8, 0), (-396.8, 1), (-793.7, 1),
                          (408.5, 1), (817.0, 1), (408.5, 0)):
        rows.append("0.1,1.0,1,%d,%s" % (loading, duty))
    (run / "force-points.csv").write_text("\n".join(rows) + "\n")
    assert offline_force_rig.run_ladder(str(tmp_path), "7") == {-1: [397, 794, 1190], 1: [408, 817]}
    assert offline_force_rig.run_ladder(str(tmp_path), "8") == {}  # no run: the rig's own levels
