"""Make boards/sim/calibration.json again: the simulated actuator's calibration, by the project's
own guided calibration on a virtual board of boards/sim.json (what `--port sim` and `host sim`
start with; host/link/virtual_board.py READY_CALIBRATION).

    .venv/bin/python boards/make_sim_calibration.py

Runs `host calibrate --port sim --yes` (4-6 minutes) in a scratch folder and copies only the
calibration file here; its run log and plots stay in the scratch folder, whose path is printed.
tests/link/test_ready_calibration.py checks that the file still matches the model; run this when
the model, the calibration or the file format changes and that test says so.
"""

import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
TARGET = REPO / "boards" / "sim" / "calibration.json"


def main():
    scratch = Path(tempfile.mkdtemp(prefix="lsea-sim-calibration-"))
    out = scratch / "calibration.json"
    print("calibrating the simulated actuator (boards/sim.json) in %s ..." % scratch, file=sys.stderr, flush=True)
    r = subprocess.run([sys.executable, "-m", "host", "calibrate", "--port", "sim", "--yes", "--out", str(out)], cwd=REPO)
    if r.returncode != 0 or not out.is_file():
        sys.exit("host calibrate failed (exit %d); %s is unchanged; the run log is in %s" % (r.returncode, TARGET, scratch))
    shutil.copyfile(out, TARGET)
    print("%s written (run log and plots: %s)" % (TARGET.relative_to(REPO), scratch))
    return 0


if __name__ == "__main__":
    sys.exit(main())
