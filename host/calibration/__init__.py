"""The calibration file: float fits to the firmware's integers, the file written and read with the
firmware's own checks, and its description for people."""
