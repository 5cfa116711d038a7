import os

import pytest

from testkit.interpreters import REPO, run_micropython

SHARED = REPO.parent / "shared"
REALDATA = SHARED / "realdata"


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
