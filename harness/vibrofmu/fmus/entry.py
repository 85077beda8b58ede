"""The file pythonfmu runs for every fmi2Instantiate: a small entry module in front of the slave's own.

pythonfmu 0.7.0 finds the slave class anew for each instance (findClass in its PySlaveInstance.cpp): it
imports the module named in resources/slavemodule.txt (once, then cached), then compiles the module's source
again and executes it with the module's dictionary as globals and a fresh dictionary as locals, walks every class
this execution created in the locals and takes the class of that name from the module. Three leaks per instance
follow, measured with tests/c_host/instance_cycles.c (issue 15: +36 MB per 1,000 plant instances):
  * every class in the locals is created again and kept alive by the list of its MRO (PySequence_List, never
    released), with the repr strings of each base: for the slave modules (all their imports and classes) 23 to
    36 KB per instance;
  * the module's dictionary (a borrowed reference, PyModule_GetDict) is released once per instance: its
    reference count falls by one each time until the dictionary is freed under the module;
  * the resources folder is inserted into sys.path once more per instance, as a string never released.
So the entry module defines no class in the locals (it binds the slave class through globals(), and under the
name "" too: finding no class, pythonfmu looks up the attribute "" of the module), takes one more reference to its
dictionary per execution (8 bytes in a list), takes the repeated sys.path entry out again and releases its
string (only when its reference count shows the leaked reference, so a pythonfmu that fixed it is left alone). The slave's module itself
is imported once, as _slave_<name>.
"""
from __future__ import annotations

import contextlib
import shutil
import sys
from pathlib import Path

ENTRY = '''"""pythonfmu entry point of the {name} FMU; the slave is {module}.py (see vibrofmu.fmus.entry for why)."""
import sys
globals()["{name}"] = __import__("{module}").{name}
globals()[""] = globals()["{name}"]  # what pythonfmu's findClass looks up when the locals hold no class
globals().setdefault("_findclass_references", []).append(globals())  # findClass releases this dict once
if sys.path[0] in sys.path[1:]:  # findClass inserted the resources folder again, a string it never releases
    _inserted = sys.path.pop(0)
    if sys.getrefcount(_inserted) == 3:  # the leaked reference, ours, getrefcount's: release the leaked one
        __import__("ctypes").pythonapi.Py_DecRef(__import__("ctypes").py_object(_inserted))
    del _inserted
'''


def implementation_module(slave: Path) -> str:
    return f"_slave_{slave.stem}"


def pythonfmu_entry(slave: Path, folder: Path) -> tuple[Path, Path]:
    """(the entry script to build the FMU from, the slave's module to pack with it), both written in folder."""
    folder.mkdir(parents=True, exist_ok=True)
    module = implementation_module(slave)
    implementation = folder / f"{module}.py"
    shutil.copyfile(slave, implementation)
    entry = folder / slave.name
    entry.write_text(ENTRY.format(name=slave.stem, module=module))
    return entry, implementation


@contextlib.contextmanager
def importable(folder: Path):
    """folder on sys.path meanwhile: pythonfmu's builder imports the entry, which imports the slave's module and
    the slave's imports (slave_support, fast_path, vibromodel) from the source folder."""
    added = str(folder) not in sys.path
    if added:
        sys.path.append(str(folder))
    try:
        yield
    finally:
        if added and str(folder) in sys.path:
            sys.path.remove(str(folder))
