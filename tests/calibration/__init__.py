"""The calibration file: writing, reading, corruption, its description for people."""
