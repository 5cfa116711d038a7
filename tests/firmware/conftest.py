"""Fixtures of the tests of the App's cases (test_app.py, test_app_safety.py, test_drive.py,
test_params_on_both.py; tests/firmware/on_both.py runs the cases): the replay data they read,
made once per test module."""

import pytest

from testkit import model


@pytest.fixture(scope="module")
def data_path(tmp_path_factory):
    """ADC codes recorded from the simulated actuator, with its model calibration (pwl pots)."""
    return model.write_replay_data(tmp_path_factory.mktemp("fw"), steps=600, duty=3000)


@pytest.fixture(scope="module")
def bcm3_data_path(tmp_path_factory):
    """The same recording with the pots as the paper's BCM-3 (bcm3 words)."""
    return model.write_replay_data(tmp_path_factory.mktemp("fw_bcm3"), steps=600, duty=3000, pots="bcm3")
