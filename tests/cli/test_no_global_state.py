"""Importing the host package changes nothing global, and neither does drawing a figure into a
file: a notebook that imports host.fitting.plots (or calls host.link.telemetry_plot.plot) keeps its
matplotlib backend. Run in a fresh interpreter, where nothing has chosen a backend yet."""

import subprocess
import sys

from testkit.interpreters import REPO

PROBE = r"""
import csv, importlib, pkgutil, sys
import matplotlib
import numpy as np

def backend():  # what is set, without resolving the automatic choice
    return dict.__getitem__(matplotlib.rcParams, "backend")

before = backend()
import host
names = [m.name for m in pkgutil.walk_packages(host.__path__, "host.") if m.name != "host.__main__"]  # runs the CLI
for name in names:
    importlib.import_module(name)
assert backend() == before, ("import", backend())
assert "matplotlib.pyplot" not in sys.modules, "an import pulled in pyplot"

from firmware.protocol import FIELDS
from host.fitting import plots as fit_plots
from host.link import telemetry_plot
from host.fitting.models import fit_model
run = sys.argv[1] + "/run.csv"
with open(run, "w", newline="") as fh:
    w = csv.writer(fh)
    w.writerow(FIELDS)
    for i in range(50):
        w.writerow([i * 1000, 100, 200, 300, 30000 + i, 30000, i, 5 * i, 30000, 10 * i, 2, 0])
telemetry_plot.plot(run, sys.argv[1] + "/run.png")
x = np.linspace(0, 4095, 200)
fit_plots.plot_fit(sys.argv[1] + "/fit.png", x, x * 60 / 4095, fit_model("bcm", x, x * 60 / 4095, 3))
# the guided steps' and the experiments' figures too
from host.experiments import displacement, force_runs
from host.guided import assembly_calibration
d1 = np.linspace(0, 60, 100)
assembly_calibration.plot_df(sys.argv[1] + "/df.png", d1, d1 * 0.01, lambda g: g * 0.01, d1 * 0.0)
displacement.plot(sys.argv[1] + "/fig7.png", [{"target": 1.0, "error": 0.1}], [{"target": 1.0, "error": 0.01}])
force_runs.plot_blocking(sys.argv[1] + "/fig8.png", [("with Df", {"t": d1, "d2": d1, "final": 60.0, "target_n": 5.0})])
assert backend() == before, ("drawing", backend())
assert "matplotlib.pyplot" not in sys.modules, "drawing a file pulled in pyplot"
print(len(names), "modules")
"""


def test_imports_and_file_figures_leave_matplotlib_alone(tmp_path):
    proc = subprocess.run([sys.executable, "-c", PROBE, str(tmp_path)], capture_output=True, text=True, cwd=REPO,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert int(proc.stdout.split()[0]) > 40
    assert (tmp_path / "run.png").stat().st_size > 10000 and (tmp_path / "fit.png").stat().st_size > 10000
