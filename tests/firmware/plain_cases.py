"""Cases for the plain path (host/link/plain_firmware.py): whatever firmware package is first on
the path runs them, the repository's (viper and native code) or its plain copy (bytecode)."""

from boards.sim.machine import for_board


def case_run_records(path, board_path="boards/sim.json"):
    """The telemetry records of one run on the simulated actuator (a physical model), a record
    every step drained from the ring through a frame slot as firmware/link.py does: position
    moves, then force holds, each tick heard. Returns the CRC-32 of every record's words (two
    builds with the same CRC computed the same words at every step), their count, and every 50th
    record in full (for a reader of a failure)."""
    import binascii
    from array import array

    from firmware.app import App
    from firmware.calibration import load_calibration
    from firmware.protocol import RECORD_WORDS

    import boards.sim.machine as sim

    app = App(board_path, None, machine=for_board(board_path))
    app.set_calibration(load_calibration(path))
    app.start()
    app.set_stream(app.board["loop_hz"])  # a record every step
    slot = memoryview(array("i", [0] * RECORD_WORDS))  # as firmware/link.py hands it to the ring
    out = {"crc": 0, "count": 0, "sample": []}

    def run(ticks):
        k = 0
        while k < ticks:
            sim.run_ticks(1)
            app.heartbeat()
            while app.telemetry.read_into(slot):
                out["crc"] = binascii.crc32(slot, out["crc"])
                if out["count"] % 50 == 0:
                    out["sample"].append(list(slot))
                out["count"] += 1
            k += 1

    run(10)
    app.set_mode("position")
    for target in (20000, 38000, 30000):
        app.set_target(target)
        run(400)
    app.set_mode("force")
    for target in (-3000, -6000, 2000):
        app.set_target(target)
        run(400)
    st = app.status()
    app.shutdown()
    import firmware.controller

    out.update(faults=st["faults"], dropped=app.telemetry.dropped, source=firmware.controller.__file__)
    return out
