"""The link to the board: frames, the protocol client, ports, flashing, the virtual board and
telemetry logs."""
