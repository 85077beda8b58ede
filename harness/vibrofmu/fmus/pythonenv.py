"""The Python a pythonfmu FMU needs, recorded as the FMU's resources/python_env.txt.

The FMU's C layer (fmu_src/pyloader.c, linked into the status shim) reads it in a host that is not Python:
it loads `libpython` globally, starts Python with PYTHONHOME = `home` and PYTHONPATH = `path` (without the
site module: sys.path is the standard library plus exactly these folders) and imports every module of
`modules`, comparing versions, before pythonfmu's library is loaded.  In a Python host of the recorded
`python_version` it appends `path` to the host's sys.path when a module does not import there; in a host of
another version it refuses with one line naming the native FMU.  The environment variable
VIBROFMU_PYTHON_ENV names another file of the same format instead (another machine, another Python);
`vibrofmu doctor --env-file FILE [--python PYTHON]` writes one.

Format: lines "key=value"; `path` is os.pathsep-separated, `modules` is "name==version" separated by spaces.
"""
from __future__ import annotations

import ast
import json
import os
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

ENV_FILE = "python_env.txt"  # in the FMU's resources (pyloader.h: VIBRO_PYTHON_ENV_FILE)
ENV_VARIABLE = "VIBROFMU_PYTHON_ENV"  # pyloader.h: VIBRO_PYTHON_ENV_VARIABLE
KEYS = ("python_version", "libpython", "home", "stdlib", "path", "modules")

# Run by the Python being described (possibly another interpreter than this one): stdlib only.
_PROBE = r"""
import importlib.util, json, os, sys, sysconfig
def site_dir(name):
    try:
        spec = importlib.util.find_spec(name)
    except (ImportError, ValueError):
        return None
    if spec is None or spec.origin in (None, "built-in", "frozen"):
        return None
    if spec.submodule_search_locations:
        return os.path.dirname(list(spec.submodule_search_locations)[0])
    return os.path.dirname(spec.origin)
def version(name):
    try:
        from importlib.metadata import version
        return version(name)
    except Exception:
        return None
modules = json.loads(sys.argv[1])
dirs = {name: site_dir(name) for name in modules}
order = [os.path.abspath(p) for p in sys.path if p and os.path.isdir(p)]
path = [p for p in order if p in {os.path.abspath(d) for d in dirs.values() if d}]
path += sorted({os.path.abspath(d) for d in dirs.values() if d} - set(path))
libdir, soname = sysconfig.get_config_var("LIBDIR"), sysconfig.get_config_var("INSTSONAME")
print(json.dumps({
    "python_version": "%d.%d" % sys.version_info[:2],
    "libpython": os.path.join(libdir, soname) if libdir and soname else "",
    "home": sys.base_prefix,
    "stdlib": sysconfig.get_path("stdlib"),
    "path": os.pathsep.join(path),
    "found": {name: d is not None for name, d in dirs.items()},
    "versions": {name: version(name) for name in modules},
}))
"""


def imported_modules(resources: Path) -> list[str]:
    """Top-level modules imported by the Python files in `resources` that are neither packed there nor in the
    standard library (what the FMU needs from its Python's site-packages), sorted; pythonfmu's library itself
    imports `pythonfmu`."""
    resources = Path(resources)
    packed = {p.stem for p in resources.iterdir() if p.suffix == ".py" or (p / "__init__.py").exists()}
    names = {"pythonfmu"}
    for source in resources.rglob("*.py"):
        for node in ast.walk(ast.parse(source.read_bytes())):
            if isinstance(node, ast.Import):
                names.update(alias.name.split(".")[0] for alias in node.names)
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names.add(node.module.split(".")[0])
    return sorted(names - packed - set(sys.stdlib_module_names))


def describe(modules: list[str], python: str | None = None) -> dict:
    """The record of `python` (default: this interpreter) for these modules; 'found' says which it has."""
    cmd = [python or sys.executable, "-c", _PROBE, json.dumps(list(modules))]
    proc = subprocess.run(cmd, capture_output=True, text=True, env={k: v for k, v in os.environ.items()
                                                                     if not k.startswith("PYTHON")})
    if proc.returncode != 0:
        last = (proc.stderr.strip().splitlines() or ["no output"])[-1]
        raise RuntimeError(f"cannot run {cmd[0]}: {last}")
    try:
        return json.loads(proc.stdout)
    except json.JSONDecodeError:  # it ran, but is no Python (or printed something else)
        raise RuntimeError(f"{cmd[0]} is not a Python interpreter (it did not answer the probe)") from None


def env_text(record: dict) -> str:
    modules = " ".join(f"{name}=={version}" if version else name
                       for name, version in sorted(record["versions"].items()))
    values = {**record, "modules": modules}
    return ("# The Python this FMU needs in a host that is not Python (read by its C layer, fmu_src/pyloader.c).\n"
            f"# {ENV_VARIABLE}=<file> replaces this file; `vibrofmu doctor --env-file` writes one.\n"
            + "".join(f"{key}={values[key]}\n" for key in KEYS))


def parse_env(text: str) -> dict[str, str]:
    out = {}
    for line in text.splitlines():
        if line.startswith("#") or "=" not in line:
            continue
        key, value = line.split("=", 1)
        out[key] = value
    return out


def missing(record: dict) -> list[str]:
    return [name for name, found in record["found"].items() if not found]


def record_for(resources: Path, python: str | None = None) -> dict:
    return describe(imported_modules(resources), python)


def pack_python_env(fmu_path: Path) -> dict:
    """Write resources/python_env.txt into the FMU (in place) for this interpreter; returns the record.
    Raises RuntimeError when this Python lacks a module the FMU imports (the FMU could not run here)."""
    fmu_path = Path(fmu_path)
    with tempfile.TemporaryDirectory() as tmp:
        with zipfile.ZipFile(fmu_path) as z:
            members = [n for n in z.namelist() if n.startswith("resources/") and n.endswith(".py")]
            z.extractall(tmp, members)
        record = record_for(Path(tmp) / "resources")
    if missing(record):
        raise RuntimeError(f"this Python lacks {', '.join(missing(record))}, which {fmu_path.name} imports")
    text = env_text(record)
    from vibrofmu.fmus.archive import rewrite_members

    name = f"resources/{ENV_FILE}"
    rewrite_members(fmu_path, lambda filename, data: None if filename == name else data, added=((name, text),))
    return record
