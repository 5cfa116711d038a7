"""lsea-kit firmware: MicroPython modules that run on the board (and unchanged under CPython in tests)."""
