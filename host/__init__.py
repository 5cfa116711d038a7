"""lsea-kit host tools: calibration math, firmware export, the board link and bench commands."""

from firmware.protocol import VERSION as __version__  # noqa: F401  (written once, with the interface)
