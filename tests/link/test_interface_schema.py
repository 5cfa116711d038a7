"""One definition of the board's interface (firmware/protocol.py), and everything that names a
part of it checked against it: the host's command calls, the parameter meanings in
docs/firmware.md, the version of the firmware, the host and the package."""

import ast
import importlib.metadata
import re
from pathlib import Path

import pytest

import host
from firmware import protocol as P

REPO = Path(__file__).resolve().parents[2]


def command_calls(path):
    """(line, command, literal arguments or None when not all literal) of every
    `x.call("name", ...)` and `x.request("name", ...)` in the file."""
    for node in ast.walk(ast.parse(path.read_text())):
        if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr in ("call", "request")
                and node.args and isinstance(node.args[0], ast.Constant) and isinstance(node.args[0].value, str)):
            rest = node.args[1:]
            literal = all(isinstance(a, ast.Constant) for a in rest)
            yield node.lineno, node.args[0].value, [a.value for a in rest] if literal else None


def test_every_command_the_host_sends_by_name_is_in_the_table_with_valid_literal_arguments():
    calls = [(p, line, name, args) for p in sorted((REPO / "host").rglob("*.py")) for line, name, args in command_calls(p)]
    assert len(calls) > 50  # the scan sees the host's calls
    bad = []
    for path, line, name, args in calls:
        try:
            if args is None:
                P.command_row(name)
            else:
                P.arguments(name, args)
        except ValueError as exc:
            bad.append("%s:%d %s" % (path.relative_to(REPO), line, exc))
    assert not bad, "\n".join(bad)


def test_the_client_refuses_a_command_the_board_would_refuse_before_sending_it():
    from host.link.board_client import BoardClient

    class Never:
        def write(self, data):
            raise AssertionError("sent: %r" % data)

    client = BoardClient.__new__(BoardClient)
    client.serial = Never()
    for args in (("mode", "sideways"), ("set", "kpos", 1), ("target", "12.5"), ("fly",)):
        with pytest.raises(ValueError):
            client.request(*args)


def test_every_parameter_is_explained_once_in_the_firmware_doc():
    text = (REPO / "docs" / "firmware.md").read_text()
    table = text[text.index("| name | meaning |"):].split("\n\n")[0]
    named = [n.strip() for row in table.splitlines()[2:] for n in row.split("|")[1].split(",")]
    assert sorted(named) == sorted(P.PARAM_NAMES)


def test_the_version_is_written_once():
    assert host.__version__ == P.VERSION == importlib.metadata.version("lsea-kit")
    for path in ("pyproject.toml", "host/__init__.py", "firmware/app.py"):
        assert not re.search(r"""version\s*=\s*["']\d""", (REPO / path).read_text(), re.I), path
