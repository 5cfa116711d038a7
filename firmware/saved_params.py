"""Controller parameters kept on the board's filesystem, so a tuned actuator keeps its gains.

File format (text, written only by `save`, read at boot by `load`):

    lsea-kit params 1
    kp_pos 900
    ...
    crc 1a2b3c4d

`crc` is the CRC32 of every byte before its line. A file is used whole or not at all: a bad
CRC, an unknown name or a value outside the table's range refuses it (with the reason), and the
table's defaults stand. `save` writes PATH.new, reads it back as the boot would (refusing a
save whose file does not give the values back, PATH untouched) and renames it over PATH; where the filesystem
cannot rename onto an existing file (FAT), PATH is removed first, and `load` then takes a
complete PATH.new when PATH is missing, so a power cut at any moment leaves the old values or
the new ones.
"""

import os

import binascii

HEADER = "lsea-kit params 1"


def _exists(path):
    try:
        os.stat(path)
        return True
    except OSError:
        return False


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


def load(path, table):
    """({index: value}, None) from the saved file, or ({}, None) when there is none, or
    ({}, reason) when there is one that cannot be used. Never raises."""
    if path is None:
        return {}, None
    use = path
    if not _exists(path):
        if not _exists(path + ".new"):
            return {}, None
        use = path + ".new"  # a save that stopped after removing the old file (FAT)
    try:
        with open(use) as f:
            text = f.read(4096)
        return _parse(text, table), None
    except MemoryError:
        return {}, "%s too large" % use
    except Exception as exc:  # ValueError from _parse or int(), OSError, UnicodeError
        why = str(exc)
        if not why:  # random bytes: MicroPython's UnicodeError says nothing
            why = "%s (not a text params file)" % type(exc).__name__
        return {}, "%s unusable: %s" % (use, why)


def save(path, table, values):
    """Write every parameter's value (`values[i]` for table row i) to `path`, atomically."""
    lines = [HEADER]
    for i, row in enumerate(table):
        lines.append("%s %d" % (row[0], values[i]))
    body = "\n".join(lines) + "\n"
    tmp = path + ".new"
    with open(tmp, "w") as f:
        f.write(body)
        f.write("crc %08x\n" % (binascii.crc32(body.encode()) & 0xFFFFFFFF))
    with open(tmp) as f:  # read back as the next boot will, before it replaces the file in use
        try:
            got = _parse(f.read(4096), table)
        except ValueError as exc:
            got = str(exc)
    if got != dict((i, values[i]) for i in range(len(table))):
        os.remove(tmp)
        raise ValueError("%s did not read back as written (%s): the saved parameters are unchanged" % (tmp, got))
    try:
        os.rename(tmp, path)
    except OSError:  # FAT cannot rename onto an existing file
        os.remove(path)
        os.rename(tmp, path)
