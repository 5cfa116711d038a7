"""A FAT volume inside an image file, mounted as a directory the way a computer mounts a
CircuitPython board's CIRCUITPY drive: through FUSE (mfusepy), with pyfatfs reading and writing
the FAT (long file names, as a computer's vfat driver writes them). This machine's kernel has no
vfat, and the emulated Pico has no USB mass storage, so a test stops the emulated board, mounts
its drive's part of the flash image here, copies with `host flash --drive`, unmounts, and starts
the board again: CircuitPython's own FAT code then reads what was written.

    with mounted(image, offset, size) as directory:
        ...                                     # plain os / pathlib calls on `directory`

The FUSE side runs in its own process (`python -m testkit.fat_drive IMAGE MOUNTPOINT`),
single-threaded; unmounting ends it and pyfatfs writes its FAT tables back as it closes.
"""

import contextlib
import errno
import os
import shutil
import stat
import subprocess
import sys
import tempfile
import time


def _fusermount():
    return shutil.which("fusermount") or shutil.which("fusermount3")


def available():
    """None when a FAT image can be mounted here, else why not (a skip reason)."""
    if not os.path.exists("/dev/fuse"):
        return "no /dev/fuse (FUSE) on this machine"
    if _fusermount() is None:
        return "no fusermount (apt-get install fuse; .ci/run does)"
    try:
        import mfusepy  # noqa: F401  # loads libfuse
        import pyfatfs  # noqa: F401
    except (ImportError, OSError, EnvironmentError) as exc:
        return "FUSE or pyfatfs cannot be loaded: %s" % exc
    return None


@contextlib.contextmanager
def mounted(image, offset=0, size=None, timeout_s=20):
    """The FAT volume in bytes [offset, offset + size) of `image` (default: all of it), mounted on
    a temporary directory (yielded); what was written is in `image` when the block ends. pyfatfs
    reads at an offset unreliably, so a volume inside a larger image is copied out and back."""
    with open(image, "rb") as f:
        whole = f.read()
    end = len(whole) if size is None else offset + size
    work = tempfile.mkdtemp(prefix="lsea-fat-")
    volume, where = os.path.join(work, "volume.img"), os.path.join(work, "mnt")
    os.mkdir(where)
    with open(volume, "wb") as f:
        f.write(whole[offset:end])
    try:
        with _fuse(volume, where, timeout_s):
            yield where
        with open(volume, "rb") as f:
            written = f.read()
        with open(image, "r+b") as f:
            f.seek(offset)
            f.write(written)
    finally:
        shutil.rmtree(work, ignore_errors=True)


@contextlib.contextmanager
def _fuse(volume, where, timeout_s):
    proc = subprocess.Popen([sys.executable, "-m", "testkit.fat_drive", volume, where],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            cwd=os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    try:
        deadline = time.monotonic() + timeout_s
        while not os.path.ismount(where):
            if proc.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError("the FAT image %s did not mount: %s" % (volume, proc.stdout.read().decode()))
            time.sleep(0.05)
        yield
    finally:
        if os.path.ismount(where):
            subprocess.run([_fusermount(), "-u", where], check=True)
        try:
            proc.wait(timeout=timeout_s)  # the FAT is written back as pyfatfs closes
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    log = proc.stdout.read().decode()
    if proc.returncode != 0 or "Traceback" in log:
        raise RuntimeError("the FUSE process for %s failed (status %d): %s" % (volume, proc.returncode, log[-2000:]))


def _operations():
    from fs.errors import DirectoryExpected, FileExpected, ResourceNotFound
    from mfusepy import FuseOSError, Operations
    from pyfatfs.PyFatFS import PyFatFS

    def oserror(fn):
        def call(*args):
            try:
                return fn(*args)
            except ResourceNotFound:
                raise FuseOSError(errno.ENOENT) from None
            except FileExpected:
                raise FuseOSError(errno.EISDIR) from None
            except DirectoryExpected:
                raise FuseOSError(errno.ENOTDIR) from None
        return call

    class FatOperations(Operations):
        """The calls a copy makes (create, write, fsync, rename over, unlink, mkdir, read), on pyfatfs."""

        use_ns = True

        def __init__(self, image):
            self.fs = PyFatFS(image, preserve_case=True)
            self.files = {}
            self.next_fh = 1

        def _on_fat(self, path):
            """`path` with each existing part spelt as on the volume: FAT names are case-insensitive
            (CircuitPython writes BOOT_OUT.TXT as a short name that a computer shows in lower
            case), and pyfatfs looks them up case-sensitively."""
            spelt = ""
            for part in [p for p in path.split("/") if p]:
                try:
                    names = self.fs.listdir(spelt or "/")
                except (ResourceNotFound, DirectoryExpected):
                    names = []
                same = [n for n in names if n == part] or [n for n in names if n.lower() == part.lower()]
                spelt += "/" + (same[0] if same else part)
            return spelt or "/"

        def destroy(self, path):
            for fh in list(self.files):
                self.release(None, fh)
            self.fs.close()

        @oserror
        def getattr(self, path, fh=None):
            path = self._on_fat(path)
            info = self.fs.getinfo(path, namespaces=["details"])
            mode = (stat.S_IFDIR | 0o755) if info.is_dir else (stat.S_IFREG | 0o644)
            ns = int((info.modified.timestamp() if info.modified else 0) * 1e9)
            return {"st_mode": mode, "st_nlink": 1, "st_size": info.size or 0,
                    "st_mtime": ns, "st_ctime": ns, "st_atime": ns}

        @oserror
        def readdir(self, path, fh):
            path = self._on_fat(path)
            return [".", ".."] + self.fs.listdir(path)

        def _keep(self, path, data, dirty):
            fh, self.next_fh = self.next_fh, self.next_fh + 1
            self.files[fh] = [path, bytearray(data), dirty]
            return fh

        # an open file is held whole in memory and written to the FAT in one piece at flush, fsync
        # and close, as a new file: pyfatfs 1.1 fails to rewrite a file that has clusters already
        # ("FREE_CLUSTER mark found in FAT cluster chain"), and at an offset into its chain
        @oserror
        def open(self, path, flags):
            path = self._on_fat(path)
            keep = not (flags & os.O_TRUNC)
            return self._keep(path, self.fs.readbytes(path) if keep else b"", not keep)

        @oserror
        def create(self, path, mode, fi=None):
            path = self._on_fat(path)
            self.fs.create(path, wipe=True)
            return self._keep(path, b"", False)

        def read(self, path, size, offset, fh):
            return bytes(self.files[fh][1][offset:offset + size])

        def write(self, path, data, offset, fh):
            f = self.files[fh]
            buf = f[1]
            if len(buf) < offset:
                buf.extend(bytes(offset - len(buf)))
            buf[offset:offset + len(data)] = data
            f[2] = True
            return len(data)

        @oserror
        def truncate(self, path, length, fh=None):
            path = self._on_fat(path)
            if fh is None:
                data = self.fs.readbytes(path)
                self._replace(path, data[:length] + bytes(max(0, length - len(data))))
                return
            f = self.files[fh]
            del f[1][length:]
            f[1].extend(bytes(length - len(f[1])))
            f[2] = True

        @oserror
        def flush(self, path, fh):
            f = self.files[fh]
            if f[2]:
                self._replace(f[0], bytes(f[1]))
                f[2] = False

        def _replace(self, path, data):
            if self.fs.exists(path):
                self.fs.remove(path)
            self.fs.writebytes(path, data)

        def fsync(self, path, datasync, fh):
            return self.flush(path, fh)

        def release(self, path, fh):
            self.flush(path, fh)
            del self.files[fh]

        @oserror
        def rename(self, old, new):
            old, there = self._on_fat(old), self._on_fat(new)
            if self.fs.exists(there):  # as FAT: not atomic (the old one goes, a new entry, the source goes)
                self.fs.remove(there)
            self.fs.move(old, there.rsplit("/", 1)[0] + "/" + new.rsplit("/", 1)[1])  # spelt as asked

        @oserror
        def unlink(self, path):
            path = self._on_fat(path)
            self.fs.remove(path)

        @oserror
        def mkdir(self, path, mode):
            path = self._on_fat(path)
            self.fs.makedir(path)

        @oserror
        def rmdir(self, path):
            path = self._on_fat(path)
            self.fs.removedir(path)

        def chmod(self, path, mode):
            return 0  # FAT keeps no modes

        def utimens(self, path, times=None):
            return 0

        def statfs(self, path):
            return {"f_bsize": 512, "f_frsize": 512, "f_blocks": 2048, "f_bfree": 1024, "f_bavail": 1024,
                    "f_namemax": 255}

    return FatOperations


def main(argv):
    from mfusepy import FUSE

    image, mountpoint = argv
    FUSE(_operations()(image), mountpoint, foreground=True, nothreads=True)


if __name__ == "__main__":
    main(sys.argv[1:])
