"""Shared fixtures: the plant FMU is built once per test session into a temporary folder.

OAFM solutions fitted during the tests go to a fresh cache folder, never the user's cache.
"""
import os
import tempfile

import pytest

os.environ["VIBROFMU_CACHE_DIR"] = tempfile.mkdtemp(prefix="vibrofmu-test-cache-")

from vibrofmu.fmus.build import build_closed_loop, build_controller, build_plant
from vibrofmu.hosts.run import run_fmu


@pytest.fixture(scope="session")
def plant_fmu(tmp_path_factory):
    return build_plant(tmp_path_factory.mktemp("fmu"))


@pytest.fixture(scope="session")
def controller_fmu(plant_fmu):
    return build_controller(plant_fmu.parent)


@pytest.fixture(scope="session")
def closed_loop_fmu(plant_fmu):
    return build_closed_loop(plant_fmu.parent)


@pytest.fixture(scope="session")
def run_plant(plant_fmu):
    """run_plant(stop_time, output_interval, **start_values) -> RunResult."""

    def run(stop_time=200.0, output_interval=0.1, **start_values):
        return run_fmu(plant_fmu, start_values, stop_time, output_interval)

    return run


def _unzipped_fixture(name):
    """<name>_unzipped: the FMU extracted once, for tests that make many instances in this process."""

    @pytest.fixture(scope="session", name=f"{name}_unzipped")
    def unzipped(request, tmp_path_factory):
        from fmpy import extract

        return extract(str(request.getfixturevalue(f"{name}_fmu")), str(tmp_path_factory.mktemp(f"{name}_unzipped")))

    return unzipped


def _starter_fixture(name):
    """start_<name>: start(stop_time=None, **start_values) -> FmuInstance in step mode at tau = 0 (the caller
    closes it); raises FMICallException if initialisation fails."""

    @pytest.fixture(scope="session", name=f"start_{name}")
    def starter(request):
        from vibrofmu.hosts.run import FmuInstance

        fmu, unzipped = request.getfixturevalue(f"{name}_fmu"), request.getfixturevalue(f"{name}_unzipped")

        def start(stop_time=None, **start_values):
            instance = FmuInstance(fmu, unzip_dir=unzipped)
            instance.fmu.setupExperiment(startTime=0.0, stopTime=stop_time)
            instance.fmu.enterInitializationMode()
            instance.set(start_values)
            instance.fmu.exitInitializationMode()
            return instance

        return start

    return starter


def _native_fixture(name):
    """native_<name>_fmu: the native FMU (fmu_src/native/) built once per session from the pythonfmu one (shared by
    tests/fmus/test_native.py, test_fuzz.py and test_nonfinite_outputs.py)."""

    @pytest.fixture(scope="session", name=f"native_{name}_fmu")
    def native(request, tmp_path_factory):
        from vibrofmu.fmus.native import build_native

        return build_native(request.getfixturevalue(f"{name}_fmu"), tmp_path_factory.mktemp(f"native_{name}"))

    return native


FMU_NAMES = ("plant", "controller", "closed_loop")
native_plant_fmu, native_controller_fmu, native_closed_loop_fmu = map(_native_fixture, FMU_NAMES)
NATIVE_NAMES = tuple(f"native_{name}" for name in FMU_NAMES)
native_plant_unzipped, native_controller_unzipped, native_closed_loop_unzipped = map(_unzipped_fixture, NATIVE_NAMES)
start_native_plant, start_native_controller, start_native_closed_loop = map(_starter_fixture, NATIVE_NAMES)
plant_unzipped, controller_unzipped, closed_loop_unzipped = map(_unzipped_fixture, FMU_NAMES)
start_plant, start_controller, start_closed_loop = map(_starter_fixture, FMU_NAMES)
