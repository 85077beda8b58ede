"""Which files the package holds (the metadata is in pyproject.toml).

`vibrofmu build` and `vibrofmu doctor` need files that live outside the two Python packages: the slaves,
C sources and headers in fmu_src/ (with any sub-folders, e.g. core/ and native/) and the C host in
tests/c_host/. Rather than moving them (they are edited where they are, and the repository layout is what
the checkout and the tests use), `package_dir` maps fmu_src/ onto the sub-package vibrofmu.fmu_src and
tests/c_host/ onto vibrofmu.c_host: setuptools copies them into the wheel from where they are (their .py
files as modules, everything else through the package_data globs below, so new C files and new
sub-folders are shipped without editing this file), and nothing is duplicated in the repository. A
setup.py rather than pyproject.toml because the package list must be discovered (find_packages: a new
sub-package such as vibrofmu.study is shipped too) and combined with these two explicit mappings, which
pyproject's static configuration cannot express. vibrofmu/paths.py finds the files in both layouts.
"""
import shutil
from pathlib import Path

from setuptools import find_packages, setup
from setuptools.command.build_py import build_py

# setuptools' scratch folder: not ./build, which holds the FMUs `vibrofmu build` writes in a checkout.
BUILD_BASE = ".setuptools-build"


class FreshBuildPy(build_py):
    """build_py from an empty folder: a file deleted from the sources must not linger in the next wheel
    (setuptools copies into build/lib and never removes what is already there)."""

    def run(self):
        scratch = Path(BUILD_BASE).resolve()
        if Path(self.build_lib).resolve().is_relative_to(scratch):  # never a folder of someone else's
            shutil.rmtree(self.build_lib, ignore_errors=True)
        super().run()


C_FILES = ["*.c", "*.h", "**/*.c", "**/*.h", "**/*.py", "**/*.txt", "**/*.def", "**/*.supp"]

setup(
    packages=[*find_packages("fmu_src"), *find_packages("harness"), "vibrofmu.fmu_src", "vibrofmu.c_host"],
    package_dir={"vibromodel": "fmu_src/vibromodel", "vibrofmu": "harness/vibrofmu",
                 "vibrofmu.fmu_src": "fmu_src", "vibrofmu.c_host": "tests/c_host"},
    package_data={"vibrofmu.hosts": ["scenes/**/*"], "vibrofmu.speed": ["*.c", "*.h"], "vibrofmu.fmu_src": C_FILES, "vibrofmu.c_host": C_FILES},
    exclude_package_data={"vibrofmu.fmu_src": ["vibromodel/**"]},  # vibromodel is installed as a package
    cmdclass={"build_py": FreshBuildPy},
    options={"build": {"build_base": BUILD_BASE}},
)
