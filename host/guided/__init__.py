"""Guided calibration: the three steps of the paper (pots, assembly Df, force) run against a
board with a person (or --yes) at the bench. See docs/guided-calibration.md."""
