"""The host's layers import only downward: nothing outside host/commands/ imports from it, and
each layer package imports only from the layers below it (docs/architecture.md). Read from the
source (every import statement, at any depth in a module), so a late import inside a function
counts as much as one at the top."""

import ast
from pathlib import Path

import host

HOST = Path(host.__file__).resolve().parent
# lowest first; a module may import from its own layer and the ones before it
LAYERS = ("fitting", "calibration", "link", "guided", "experiments", "api", "commands")
# outside the layer packages: shared by all (errors, terminal) or the command line itself
SHARED = {"host", "host.errors", "host.terminal"}
COMMAND_LINE = {"host.cli", "host.__main__", "host.command_table"}


def module_name(path):
    return ".".join(("host",) + path.relative_to(HOST).with_suffix("").parts).removesuffix(".__init__")


def host_imports(path):
    """The host.* modules `path` imports (absolute names)."""
    tree = ast.parse(path.read_text(), str(path))
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names if a.name.split(".")[0] == "host")
        elif isinstance(node, ast.ImportFrom) and node.module and node.module.split(".")[0] == "host" and not node.level:
            out.add(node.module)
            out.update("%s.%s" % (node.module, a.name) for a in node.names if (HOST.parent / node.module.replace(".", "/") / a.name).exists()
                       or (HOST.parent / (node.module.replace(".", "/") + "/" + a.name + ".py")).exists())
    return out


def layer_of(name):
    """The layer package of host module `name` (host.api, the Python API, is a layer of one module)."""
    parts = name.split(".")
    return parts[1] if len(parts) > 1 and parts[1] in LAYERS else None


def modules():
    return sorted(p for p in HOST.rglob("*.py"))


def test_every_host_module_is_in_a_layer_or_shared():
    loose = [module_name(p) for p in modules()
             if layer_of(module_name(p)) is None and module_name(p) not in SHARED | COMMAND_LINE]
    assert not loose, "modules outside the layers (docs/architecture.md): %s" % loose


def test_nothing_outside_the_commands_imports_from_them():
    bad = [(module_name(p), name) for p in modules() for name in sorted(host_imports(p))
           if layer_of(name) == "commands" and layer_of(module_name(p)) != "commands"
           and module_name(p) not in COMMAND_LINE]
    assert not bad, "imports up into host.commands: %s" % bad


def test_layers_import_only_downward():
    bad = []
    for p in modules():
        mine = layer_of(module_name(p))
        if mine is None:
            continue
        for name in sorted(host_imports(p)):
            theirs = layer_of(name)
            if theirs is not None and LAYERS.index(theirs) > LAYERS.index(mine):
                bad.append("%s imports %s" % (module_name(p), name))
    assert not bad, "imports up a layer:\n" + "\n".join(bad)


def test_the_check_sees_an_upward_import(tmp_path):
    """The scan itself: an import of host.commands inside a function is found."""
    path = tmp_path / "m.py"
    path.write_text("def f():\n    from host.commands.fit import run\n    import host.guided.acquire\n")
    assert {"host.commands.fit", "host.guided.acquire"} <= host_imports(path)


def test_only_the_connection_opens_a_client():
    """One door to a board: a BoardClient is built only by host.link.connect.Connection (open,
    reconnect); everything else, host flash's own steps included, opens a Connection."""
    builders = []
    for p in modules():
        for node in ast.walk(ast.parse(p.read_text(), str(p))):
            if isinstance(node, ast.Call) and getattr(node.func, "id", getattr(node.func, "attr", None)) == "BoardClient":
                builders.append(module_name(p))
    assert builders and set(builders) == {"host.link.connect"}, builders
