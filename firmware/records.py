"""Small text records the firmware keeps across boots: why run() last ended, the saved parameters.

On MicroPython a record is a file beside main.py (FileRecord). On CircuitPython it is a slot of
`microcontroller.nvm` (NvmRecord): the CIRCUITPY drive belongs to the computer that mounts it
and is read-only to code, and boot.py could make it writable only by hiding it from the
computer, which would stop its owner copying files onto it. hal.record picks one.

A record is used whole or not at all:
- a file is written as NAME.new, read back, and renamed over NAME; where the filesystem cannot
  rename onto an existing file (FAT), NAME is removed first, and read() then takes a complete
  NAME.new when NAME is missing;
- an nvm slot carries its length and a CRC32, so a damaged one is refused, never half-used.
  CircuitPython rewrites the nvm's whole flash sector for any write (erase, then program: a few
  milliseconds), so a power cut in those milliseconds can lose the slot; the firmware then uses
  its defaults and says why (saved parameters) or reports no earlier exit.
"""

import os

import binascii


def exists(path):
    """Whether a file is at `path` (MicroPython's os has no os.path)."""
    try:
        os.stat(path)
        return True
    except OSError:
        return False


class FileRecord:
    """A record in the file `path`."""

    def __init__(self, path):
        self.name = path

    def read(self, limit):
        """Up to `limit` characters of the text, or None when there is no record. Raises OSError
        or ValueError (UnicodeError) when there is one that cannot be read."""
        use = self.name
        if not exists(use):
            use += ".new"  # a write that stopped after removing the old file (FAT)
            if not exists(use):
                return None
        with open(use) as f:
            return f.read(limit)

    def write(self, text):
        """Replace the record with `text` (ValueError when it does not read back as written, the
        old record untouched; OSError from the filesystem)."""
        tmp = self.name + ".new"
        with open(tmp, "w") as f:
            f.write(text)
        with open(tmp) as f:
            back = f.read(len(text) + 1)
        if back != text:
            os.remove(tmp)
            raise ValueError("%s did not read back as written" % tmp)
        try:
            os.rename(tmp, self.name)
        except OSError:  # FAT cannot rename onto an existing file
            os.remove(self.name)
            os.rename(tmp, self.name)


_MAGIC = b"LR"
_HEAD = 4  # magic, text length (2 bytes)
_TAIL = 4  # CRC32 of the length and the text


class NvmRecord:
    """A record in bytes [offset, offset + size) of `nvm` (microcontroller.nvm or any bytearray)."""

    def __init__(self, nvm, offset, size, name):
        self.nvm = nvm
        self.offset = offset
        self.room = size - _HEAD - _TAIL  # the longest text
        self.name = name

    def read(self, limit):
        """Up to `limit` characters of the text, or None when there is no record (ValueError when
        there is one that cannot be read)."""
        a = self.offset
        head = bytes(self.nvm[a:a + _HEAD])
        if head[0:2] != _MAGIC:
            if head == b"\xff" * _HEAD:  # erased: never written
                return None
            raise ValueError("%s holds no record" % self.name)
        n = head[2] | (head[3] << 8)
        if n > self.room:
            raise ValueError("%s damaged (length %d)" % (self.name, n))
        body = bytes(self.nvm[a + 2:a + _HEAD + n])
        if bytes(self.nvm[a + _HEAD + n:a + _HEAD + n + _TAIL]) != _crc_bytes(body):
            raise ValueError("%s damaged (bad CRC)" % self.name)
        return body[2:].decode()[:limit]

    def write(self, text):
        """Replace the record with `text` (ValueError when it does not fit or does not read back as
        written)."""
        data = text.encode()
        n = len(data)
        if n > self.room:
            raise ValueError("%s holds at most %d bytes, not %d" % (self.name, self.room, n))
        body = bytes((n & 0xFF, n >> 8)) + data
        blob = _MAGIC + body + _crc_bytes(body)
        a = self.offset
        self.nvm[a:a + len(blob)] = blob
        if bytes(self.nvm[a:a + len(blob)]) != blob:
            raise ValueError("%s did not read back as written" % self.name)


def _crc_bytes(data):
    crc = binascii.crc32(data) & 0xFFFFFFFF
    return bytes((crc & 0xFF, (crc >> 8) & 0xFF, (crc >> 16) & 0xFF, crc >> 24))
