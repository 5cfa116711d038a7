"""lsea-kit host tools: calibration math, firmware export, the board link and bench commands."""

__version__ = "0.1.0"
