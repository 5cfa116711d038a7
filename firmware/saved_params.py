"""Controller parameters kept on the board, so a tuned actuator keeps its gains.

Format (text, written only by `save`, read at boot by `load`):

    lsea-kit params 1
    kp_pos 900
    ...
    crc 1a2b3c4d

`crc` is the CRC32 of every byte before its line. A file is used whole or not at all: a bad
CRC, an unknown name or a value outside the table's range refuses it (with the reason), and the
table's defaults stand. It lives in a record (firmware/records.py: a file on MicroPython, a slot
of microcontroller.nvm on CircuitPython), which `save` replaces whole after checking that the text
reads back as these values.
"""

import binascii

HEADER = "lsea-kit params 1"


def _parse(text, table):
    """{index: value} of a file's text, or raise ValueError saying why it cannot be used."""
    lines = text.split("\n")
    while lines and lines[-1] == "":
        lines.pop()
    if len(lines) < 2 or lines[0] != HEADER:
        raise ValueError("not an lsea-kit params file")
    last = lines[-1].split()
    body = "\n".join(lines[:-1]) + "\n"
    if len(last) != 2 or last[0] != "crc" or last[1] != "%08x" % (binascii.crc32(body.encode()) & 0xFFFFFFFF):
        raise ValueError("CRC mismatch: the file is damaged")
    index = {}
    for i, row in enumerate(table):
        index[row[0]] = i
    values = {}
    for line in lines[1:-1]:
        words = line.split()
        if len(words) != 2 or words[0] not in index:
            raise ValueError("unknown parameter line %r" % line[:40])
        i = index[words[0]]
        value = int(words[1])
        if not table[i][2] <= value <= table[i][3]:
            raise ValueError("%s %d outside %d..%d" % (words[0], value, table[i][2], table[i][3]))
        values[i] = value
    return values


def load(record, table):
    """({index: value}, None) from the saved record (firmware/records.py), or ({}, None) when
    there is none, or ({}, reason) when there is one that cannot be used. Never raises."""
    if record is None:
        return {}, None
    try:
        text = record.read(4096)
        if text is None:
            return {}, None
        return _parse(text, table), None
    except MemoryError:
        return {}, "%s too large" % record.name
    except Exception as exc:  # ValueError from _parse or int(), OSError, UnicodeError
        why = str(exc)
        if not why:  # random bytes: MicroPython's UnicodeError says nothing
            why = "%s (not a text params file)" % type(exc).__name__
        return {}, "%s unusable: %s" % (record.name, why)


def save(record, table, values):
    """Replace the saved record with every parameter's value (`values[i]` for table row i)."""
    lines = [HEADER]
    for i, row in enumerate(table):
        lines.append("%s %d" % (row[0], values[i]))
    body = "\n".join(lines) + "\n"
    text = body + "crc %08x\n" % (binascii.crc32(body.encode()) & 0xFFFFFFFF)
    try:  # read as the next boot will, before anything is written
        got = _parse(text, table)
    except ValueError as exc:
        got = str(exc)
    if got != dict((i, values[i]) for i in range(len(table))):
        raise ValueError("%s would not read back as these values (%s): the saved parameters are unchanged"
                         % (record.name, got))
    record.write(text)
