"""What the emulated-Pico tests (MicroPython and CircuitPython) check against the plant: a move to
40 mm and a -5 N force hold, judged by the simulated actuator, not by the firmware's estimate."""


def move_and_hold(pico, timeout_s, settle_s=0.0, rate=1000):
    """The move and the hold on `pico` (an EmulatedPico with our firmware and the model
    calibration); `settle_s` of board time (telemetry at `rate` Hz) passes before the gauge is
    read: a slower loop's block follows the spring over more of it. Returns the status after."""
    from host.api import Board

    pico.rig({"load": {"kind": "none"}, "reference": "pot2"})
    with Board(pico.path) as board:
        moved = board.move(40.0, timeout_s=timeout_s)
        assert moved.reached, moved
        block = pico.state()["block_mm"]
        assert abs(block - 40.0) < 0.25, block  # the plant's block, not the firmware's estimate
        # the gauge on the 60 mm side, its fibre taut below 45 mm: the block at 40 mm pulls it
        pico.rig({"load": {"kind": "gauge", "side": "high", "anchor_mm": 45.0}})
        held = board.force(-5.0, timeout_s=timeout_s, hold=True)
        assert held.reached, held
        if settle_s:
            board.record(settle_s, rate=rate)
        tension = pico.state()["gauge_tension_n"]
        # what the gauge feels: 4.92-4.94 N on the MicroPython Pico, 5.00-5.15 N on CircuitPython at
        # 250 Hz (2026-11-27, the model calibration's order-7 F0; its cubic F0 read 0.3 N strong)
        assert abs(tension - 5.0) < 0.3, tension
        board.stop()
        status = board.status()
    pico.rig({"load": {"kind": "none"}})
    assert status["faults"] == [], status
    return status
