"""The structure's guards (docs/architecture.md): the import contracts of pyproject.toml hold (the model below the
harness and free of host libraries, the harness's layers, no import cycle at any depth, imports inside functions
included), and the pythonfmu slaves import only the model, their support modules and their run-time libraries.

.ci/run runs `lint-imports` too; here the same contracts run with the test suite, so that a change that breaks
one fails the README's test command as well."""
import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SLAVES = sorted((ROOT / "fmu_src").glob("*.py"))
# what a slave may import: the model, what the slaves share, pythonfmu, numpy, and Python's standard library
SLAVE_IMPORTS = {"vibromodel", "slave_support", "fast_path", "pythonfmu", "numpy", *sys.stdlib_module_names}


def test_the_import_contracts_hold():
    lint = Path(sys.executable).with_name("lint-imports")
    proc = subprocess.run([str(lint) if lint.exists() else "lint-imports", "--no-cache"], cwd=ROOT,
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-2000:]


@pytest.mark.parametrize("slave", SLAVES, ids=[path.name for path in SLAVES])
def test_the_slaves_import_only_the_model_and_their_run_time(slave):
    imported = set()
    for node in ast.walk(ast.parse(slave.read_text())):
        if isinstance(node, ast.Import):
            imported.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0:
            imported.add(node.module.split(".")[0])
    assert SLAVES and imported, slave
    assert imported <= SLAVE_IMPORTS, f"{slave.name} imports {sorted(imported - SLAVE_IMPORTS)}"


# the project's own packages and modules: a private name (one leading underscore) of these stays in its module
PROJECT_MODULES = {"vibromodel", "vibrofmu", "slave_support", "fast_path", "message_text", "conftest",
                   *(path.stem for path in SLAVES)}


def private(name: str) -> bool:
    """One leading underscore (not a dunder, not a sunder like ctypes' _fields_)."""
    return name.startswith("_") and not name.endswith("_")


PACKAGE_ROOTS = {"vibromodel": ROOT / "fmu_src" / "vibromodel", "vibrofmu": ROOT / "harness" / "vibrofmu"}


def is_module(dotted: str) -> bool:
    """Whether a dotted name is one of the project's modules or packages (a file or folder in the tree)."""
    head, *rest = dotted.split(".")
    if head not in PACKAGE_ROOTS:
        return head in PROJECT_MODULES
    folder = PACKAGE_ROOTS[head].joinpath(*rest)
    return folder.with_suffix(".py").is_file() or (folder / "__init__.py").is_file()


def absolute(path: Path, node: ast.ImportFrom) -> str:
    """The absolute module name of a (relative) `from ... import`."""
    if node.level == 0:
        return node.module
    package = path.parent.relative_to(ROOT / ("fmu_src" if path.is_relative_to(ROOT / "fmu_src") else "harness"))
    parts = list(package.parts)[:len(package.parts) - node.level + 1]
    return ".".join(parts + ([node.module] if node.module else []))


def private_uses(path: Path) -> list[str]:
    """`from <project module> import _name` and `<imported project module>._name` in the file."""
    tree, uses, modules = ast.parse(path.read_text()), [], set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            source = absolute(path, node)
            if not is_module(source):
                continue
            for alias in node.names:
                if private(alias.name):
                    uses.append(f"{path.relative_to(ROOT)}:{node.lineno}: from {source} import {alias.name}")
                elif is_module(f"{source}.{alias.name}"):
                    modules.add(alias.asname or alias.name)
        elif isinstance(node, ast.Import):
            modules.update(alias.asname or alias.name.split(".")[0] for alias in node.names if is_module(alias.name))
    for node in ast.walk(tree):
        if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in modules
                and private(node.attr)):
            uses.append(f"{path.relative_to(ROOT)}:{node.lineno}: {node.value.id}.{node.attr}")
    return uses


def test_no_private_name_is_used_across_modules():
    """A name with a leading underscore is its module's own: another module (the tests included) that needs it
    needs a public name."""
    files = [path for folder in ("fmu_src", "harness", "tests") for path in sorted((ROOT / folder).rglob("*.py"))]
    assert len(files) > 100
    uses = [use for path in files for use in private_uses(path)]
    assert uses == []
