"""Where the files that `build` and `doctor` need are: the one resolver (the C compiler and its flags:
vibrofmu.fmus.toolchain, re-exported here as c_compiler / NoCompiler).

Installed from a wheel (`pip install .`, `pip install dist/*.whl`), the repository's fmu_src/ (slaves, C
sources and headers, including any sub-folders such as core/ and native/) is inside the package as
vibrofmu/fmu_src/ and tests/c_host/ as vibrofmu/c_host/: setup.py maps those folders into the package
(see the comment there). In a checkout (editable install, or the tests run from the repository) the
package has no such folders and the files are read where they are, <repository>/fmu_src and
<repository>/tests/c_host. The Python model (vibromodel) is an ordinary installed package in both cases.
"""
from __future__ import annotations

from pathlib import Path

PACKAGE_DIR = Path(__file__).resolve().parent
SCENES_DIR = PACKAGE_DIR / "hosts" / "scenes"
DEFAULT_SCENE = SCENES_DIR / "closed_loop.toml"  # the closed-loop co-simulation scene (source of closed_loop.ssp)
PLANT_NAME = "HertzEAOscillator.fmu"  # the FMU files `vibrofmu build` writes
CONTROLLER_NAME = "AdaptiveLyapunovController.fmu"
CLOSED_LOOP_NAME = "HertzEAClosedLoop.fmu"
PLANT_MODEL = "HertzEAOscillator"
_CHECKOUT = PACKAGE_DIR.parents[1]  # <repository> when this file is <repository>/harness/vibrofmu/paths.py


def _located(installed: Path, checkout: Path, marker: str) -> Path:
    """`installed` if it holds `marker`, else `checkout` if it does; FileNotFoundError otherwise."""
    for folder in (installed, checkout):
        if (folder / marker).is_file():
            return folder
    raise FileNotFoundError(f"{marker} is neither in {installed} (installed package) nor in {checkout} "
                            f"(checkout): reinstall vibrofmu")


FMU_SRC = _located(PACKAGE_DIR / "fmu_src", _CHECKOUT / "fmu_src", "HertzEAOscillator.py")
C_HOST_DIR = _located(PACKAGE_DIR / "c_host", _CHECKOUT / "tests" / "c_host", "fmi2_host.c")


def vibromodel_dir() -> Path:
    """The vibromodel package the FMUs carry: the one this Python imports."""
    import vibromodel

    return Path(vibromodel.__file__).resolve().parent


def build_dir() -> Path:
    """The default output folder of `vibrofmu build` and of the commands that build missing FMUs:
    ./build of the current directory."""
    return Path.cwd() / "build"
