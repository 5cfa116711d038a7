import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))

from micropython_runner import REPO, run_micropython  # noqa: E402

SHARED = REPO.parent / "shared"
REALDATA = SHARED / "realdata"


@pytest.fixture
def mpy():
    """Call as mpy(source) to run program text under the real MicroPython unix port."""
    return run_micropython


@pytest.fixture
def realdata_dir():
    if not REALDATA.is_dir():
        pytest.fail("../shared/realdata is missing: CI and developers have it beside the checkout")
    return REALDATA
