"""The package installs, the CLI answers, and the real MicroPython interpreter is available."""

import subprocess
import sys

from testkit.interpreters import run_micropython


def test_cli_help_lists_commands_and_the_exit_statuses():
    out = subprocess.run([sys.executable, "-m", "host", "--help"], capture_output=True, text=True)
    assert out.returncode == 0
    assert "usage: host" in out.stdout
    said = " ".join(out.stdout.split())
    assert "exit status, the same for every command: 0 done; 1 measured, and the goal missed" in said
    assert "; 2 the input or the setup" in said and "; 130 Ctrl-C; 141" in said


def test_every_command_returns_a_named_exit_status():
    """0, 1 and 2 mean one thing each in every command (host.errors.EXIT_STATUSES): a command
    returns DONE, MISSED or USER_ERROR by name, never a bare number whose meaning it chose."""
    import ast
    from pathlib import Path

    import host

    root = Path(host.__file__).parent
    bare = []
    for path in sorted((root / "commands").glob("*.py")) + [root / "cli.py"]:
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Return) and node.value is not None:
                values = [node.value.body, node.value.orelse] if isinstance(node.value, ast.IfExp) else [node.value]
                bare += ["%s:%d" % (path.name, node.lineno) for v in values
                         if isinstance(v, ast.Constant) and isinstance(v.value, int) and not isinstance(v.value, bool)]
    assert not bare, "bare exit statuses: %s" % bare


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


def test_the_readme_command_table_is_the_one_the_parser_makes():
    """README's table of commands is made from the parser (host/command_table.py): a command, an
    option or a help text changed without `python -m host.command_table --write` fails here."""
    from host import command_table
    from host.cli import build_parser

    readme = command_table.README.read_text()
    assert command_table.in_readme(readme) == command_table.table(), (
        "README.md's command table is stale: run python -m host.command_table --write")
    made = command_table.table()
    sub = next(a for a in build_parser()._actions if a.dest == "command")
    assert all("| `host %s" % name in made for name in sub.choices)  # every command has its row


def test_every_tag_in_the_firmware_is_explained_in_docs_firmware_md():
    """The firmware says why once, in docs/firmware.md under a tag, and carries the tag and one
    line (issue 27): a tag in the code with no entry there, or an entry no code carries, fails."""
    import re
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    used = set()
    for path in (root / "firmware").glob("*.py"):
        used |= set(re.findall(r"#\s*\[([a-z]+(?:-[a-z]+)*)\]", path.read_text()))
    explained = set(re.findall(r"^- \*\*\[([a-z-]+)\]\*\*", (root / "docs" / "firmware.md").read_text(), re.M))
    assert used and used == explained, "in the code only: %s; in docs/firmware.md only: %s" % (
        sorted(used - explained), sorted(explained - used))


def test_the_calibration_options_default_as_the_cli_does():
    """`host experiment paper` takes the options it has no flag for from Options' defaults, and
    `host calibrate` takes its flags' defaults from there too: with no flags the two agree (a
    default changed in one place only would fail here)."""
    from host.cli import build_parser
    from host.commands.calibrate import options_from
    from host.guided.flow import Options

    args = build_parser().parse_args(["calibrate", "--out", "/tmp/lsea-unused/calibration.json", "--no-flash"])
    args.plots = "/tmp/lsea-unused"
    from_cli, default = options_from(args), Options()
    for name in ("reference", "manual_points", "model", "order", "budget", "duty", "df_order", "force_order",
                 "gauge_sides", "friction", "trim", "anchor_mm", "rounds", "levels", "max_duty", "force_range", "fix"):
        assert getattr(from_cli, name) == getattr(default, name), name
    experiment = build_parser().parse_args(["experiment", "paper", "--out", "/tmp/lsea-unused"])
    assert experiment.rounds == default.rounds
