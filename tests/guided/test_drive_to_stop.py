"""A drive to an end stop that the host's silence cut short goes on to the stop.

Under load (the suite beside two robustness runs, stop 49) the host fell silent for longer than
host_timeout_ms in the middle of a drive: the firmware stopped the motor and put the opened
stroke limits back, the pots stood still, and the stall was taken for the end stop (a zero 0.25-2.2
mm off). Here the host falls silent on purpose, once, mid-drive. The real unix port, firmware, pty
and pyserial."""

import time

import numpy as np
import pytest

from host.errors import UserError
from host.guided import acquire
from host.link.board_client import BoardClient
from host.link.virtual_board import VirtualBoard


ASLEEP_S = 2.0  # the host's silence: twice the board's host_timeout_ms (a trip puts every parameter back to boot values)


def _falling_silent(monkeypatch, times):
    """The host stops reading and sending for ASLEEP_S, `times` times, each 0.3 board seconds into a drive."""
    stalled = acquire._stalled
    left = [times]
    asleep_in_this_drive = [False]

    def host_asleep_then_stalled(records, seconds, hz=acquire.STREAM_HZ):
        if seconds < 0.3:  # a new drive (records come in order; the first reach 0.3 s after a while)
            asleep_in_this_drive[0] = False
        elif left[0] and not asleep_in_this_drive[0]:
            left[0] -= 1
            asleep_in_this_drive[0] = True
            time.sleep(ASLEEP_S)
        return stalled(records, seconds, hz)

    monkeypatch.setattr(acquire, "_stalled", host_asleep_then_stalled)


def _at_rest(client, seconds=0.3):
    return acquire.mean(acquire.collect(client, seconds), "raw2")


def test_a_drive_the_host_timeout_stopped_goes_on_to_the_end_stop(model_calibration, monkeypatch):
    with VirtualBoard(calibration=model_calibration) as vb, BoardClient(vb.path) as client:
        limits = client.call("status")["stroke_um"]
        _falling_silent(monkeypatch, 1)
        with acquire.open_stroke(client):
            records = acquire.drive_to_stop(client, -2500)
            # the silence did stop the motor on the way (else this test proves nothing)
            assert acquire.host_went_silent(records)
            stopped_at = _at_rest(client)
            monkeypatch.undo()
            again = acquire.drive_to_stop(client, -2500)
        # a second drive, with nothing in its way, finds the block already at the stop
        assert not acquire.host_went_silent(again)
        assert abs(_at_rest(client) - stopped_at) <= acquire.STALL_CODES, "the first drive stopped short of the stop"
        assert np.ptp(again[:, acquire.COL["raw2"]]) <= 2 * acquire.STALL_CODES
        assert client.call("status")["stroke_um"] == limits


def test_a_host_that_keeps_falling_silent_is_an_error_not_an_end_stop(model_calibration, monkeypatch):
    with VirtualBoard(calibration=model_calibration) as vb, BoardClient(vb.path) as client:
        _falling_silent(monkeypatch, acquire.DRIVE_TRIES)
        with acquire.open_stroke(client), pytest.raises(UserError, match="fell silent"):
            acquire.drive_to_stop(client, -2500)


def test_a_drive_after_the_host_fell_silent_between_two_still_reaches_the_end_stop(model_calibration):
    """Silent with the motor off, between two drives: the firmware put the opened limits back;
    the next drive opens them again instead of stopping at the soft limit (0.5 mm inside the stop)."""
    with VirtualBoard(calibration=model_calibration) as vb, BoardClient(vb.path) as client:
        with acquire.open_stroke(client):
            acquire.drive_to_stop(client, 2500)
            time.sleep(ASLEEP_S)
            assert client.call("status")["params_temporary"] == []  # the board did put them back
            acquire.drive_to_stop(client, -2500)
            low = _at_rest(client)
        with acquire.open_stroke(client):  # opened afresh, with the host awake
            again = acquire.drive_to_stop(client, -2500)
        assert abs(_at_rest(client) - low) <= acquire.STALL_CODES, "the drive stopped at the soft limit"
        assert np.ptp(again[:, acquire.COL["raw2"]]) <= 2 * acquire.STALL_CODES


def test_a_hard_sweep_runs_its_fast_leg_at_full_duty_at_most(model_calibration):
    """The gain step sweeps harder when the block stalls against its weight (gain_sweep.DUTY_STEP);
    at duty 5000 the sweep's fast leg to the low stop (three times the duty) was 15000, which the
    firmware refuses: a drawn actuator's run stopped there (stop 55)."""
    with VirtualBoard(calibration=model_calibration) as vb, BoardClient(vb.path) as client:
        records, direction = acquire.sweep(client, 5000)
    assert (direction > 0).sum() > 20 and (direction < 0).sum() > 20


def test_a_fitted_sweep_takes_every_step_and_still_finds_both_stops(model_calibration):
    """The pots and gain steps sweep at SWEEP_HZ (1 kHz: every step of the loop) for five times the
    samples of the 200 Hz stream; the stall that ends each run, and the records standing still at
    each stop, are judged by the records' own times, so they are the same 0.4 s at either rate."""
    with VirtualBoard(calibration=model_calibration) as vb, BoardClient(vb.path) as client:
        slow, slow_stops = {}, {}
        plain = acquire.sweep(client, 1500, stops=slow_stops)[0]
        fast = acquire.sweep(client, 1500, stops=slow, hz=acquire.SWEEP_HZ)[0]
    assert len(fast) > 3.5 * len(plain), (len(fast), len(plain))
    for stops in (slow_stops, slow):
        for end in ("low", "high"):
            t = stops[end][:, acquire.COL["t_us"]]
            assert 0.35e6 <= (t[-1] - t[0]) <= 0.41e6, (end, t[-1] - t[0])
            assert np.ptp(stops[end][:, acquire.COL["raw2"]]) <= acquire.STALL_CODES
    assert abs(np.median(slow["high"][:, acquire.COL["raw2"]]) - np.median(slow_stops["high"][:, acquire.COL["raw2"]])) <= 3
