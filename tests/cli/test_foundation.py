"""The package installs, the CLI answers, and the real MicroPython interpreter is available."""

import subprocess
import sys

from testkit.interpreters import run_micropython


def test_cli_help_lists_commands():
    out = subprocess.run([sys.executable, "-m", "host", "--help"], capture_output=True, text=True)
    assert out.returncode == 0
    assert "usage: host" in out.stdout


def test_micropython_is_real_and_locks_heap():
    proc = run_micropython(
        "import sys, micropython\n"
        "print(sys.implementation.name)\n"
        "def f():\n"
        "    return [1]\n"
        "micropython.heap_lock()\n"
        "try:\n"
        "    f()\n"
        "    print('allocated')\n"
        "except MemoryError:\n"
        "    print('locked')\n"
        "micropython.heap_unlock()\n"
    )
    assert proc.stdout.split() == ["micropython", "locked"]


def test_firmware_package_imports_under_micropython():
    proc = run_micropython("import firmware\nprint('ok')")
    assert proc.stdout.strip() == "ok"


def test_missing_shared_data_skips_with_the_reason_but_fails_under_ci(tmp_path, monkeypatch):
    import pytest
    from tests.conftest import shared_dir

    missing = tmp_path / "shared" / "realdata"
    monkeypatch.delenv("CI", raising=False)
    with pytest.raises(pytest.skip.Exception, match="realdata is missing: the curves"):
        shared_dir(missing, "the curves")
    monkeypatch.setenv("CI", "true")
    with pytest.raises(pytest.fail.Exception, match="under CI"):
        shared_dir(missing, "the curves")
    missing.mkdir(parents=True)
    assert shared_dir(missing, "the curves") == missing  # present: no skip, CI or not


def test_the_readme_command_table_names_every_command():
    """The README's table is written by hand; a command missing from it (host show was) fails here."""
    from pathlib import Path

    from host.cli import build_parser

    readme = (Path(__file__).resolve().parents[2] / "README.md").read_text()
    table = readme.split("## Commands", 1)[1].split("\n\n", 1)[0]
    sub = next(a for a in build_parser()._actions if a.dest == "command")
    missing = [name for name in sub.choices if "`host %s" % name not in table]
    assert not missing, "commands missing from README's table: %s" % missing
