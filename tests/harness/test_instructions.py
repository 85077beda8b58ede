"""vibrofmu.speed.instructions: the environment an FMU built by an older checkout needs in the C host."""
import os
import sys
from pathlib import Path

from vibrofmu.speed.instructions import legacy_environment


def test_legacy_environment_names_this_pythons_shared_library_home_and_packages():
    """The pre-drop-in pythonfmu FMUs load this interpreter's libpython (LD_PRELOAD) and import numpy, scipy and
    pythonfmu from its site-packages: each path must exist and belong to the running Python, or the older FMU fails
    to load in the C host ("cannot load inner library")."""
    env = legacy_environment()
    library = Path(env["LD_PRELOAD"])
    assert library.is_file() and library.name.startswith(f"libpython{sys.version_info[0]}.{sys.version_info[1]}")
    assert Path(env["PYTHONHOME"]).resolve() == Path(sys.base_prefix).resolve()
    packages = Path(env["PYTHONPATH"])
    assert (packages / "numpy").is_dir() and os.path.commonpath([packages, sys.prefix]) == sys.prefix
