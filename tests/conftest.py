import os
import shutil
import tempfile

import pytest

from testkit.interpreters import REPO, run_micropython

SHARED = REPO.parent / "shared"
REALDATA = SHARED / "realdata"


def pytest_configure(config):
    """One mpy-cross cache for the whole run (host/link/flashing.py: $LSEA_MPY_CACHE), made by the
    controlling process before it starts the xdist workers, which inherit it, as do the `host
    flash` processes the tests start: every flash of the run compiles the same firmware, keyed by
    compiler, arguments and source bytes, so each module is compiled once, not once per flash."""
    if hasattr(config, "workerinput") or os.environ.get("LSEA_MPY_CACHE"):
        return
    config._lsea_mpy_cache = tempfile.mkdtemp(prefix="lsea-mpy-cache-")
    os.environ["LSEA_MPY_CACHE"] = config._lsea_mpy_cache


def pytest_unconfigure(config):
    made = getattr(config, "_lsea_mpy_cache", None)
    if made:
        shutil.rmtree(made, ignore_errors=True)
        os.environ.pop("LSEA_MPY_CACHE", None)


def shared_dir(path, what):
    """`path` (under ../shared, beside the checkout) when it is there. When it is not: a skip
    with the reason on a developer's machine (a fresh clone elsewhere has no ../shared), a
    failure under CI (env CI=true), where its absence means the runner is set up wrong and
    the tests that need it would otherwise pass by skipping."""
    if path.is_dir():
        return path
    text = "%s is missing: %s (expected beside the checkout, at %s)" % (
        os.path.relpath(path, REPO), what, path)
    if os.environ.get("CI", "").strip().lower() == "true":
        pytest.fail(text + "; under CI (CI=true) it must be there")
    pytest.skip(text)


@pytest.fixture
def mpy():
    """Call as mpy(source) to run program text under the real MicroPython unix port."""
    return run_micropython


@pytest.fixture
def realdata_dir():
    """../shared/realdata: the real measured ADC curves (third-party, not in this repository)."""
    return shared_dir(REALDATA, "the real measured ADC curves")


@pytest.fixture(scope="module")
def model_calibration(tmp_path_factory):
    """Path of the model calibration of boards/sim.json (testkit.model), written once per module
    with the real calibration-file code: what the tests that drive the virtual board flash."""
    from testkit.model import write_model_calibration

    path = tmp_path_factory.mktemp("cal") / "cal.json"
    write_model_calibration(path, date="2026-03-03")
    return str(path)
