"""The link to the board: frames, the protocol client and its schema checks, board time, ports,
flashing, parameters, telemetry logs and the virtual board."""
