"""Shared fixtures: the plant FMU is built once per test session into a temporary folder."""
import pytest

from vibrofmu.build import build_plant
from vibrofmu.run import run_fmu


@pytest.fixture(scope="session")
def plant_fmu(tmp_path_factory):
    return build_plant(tmp_path_factory.mktemp("fmu"))


@pytest.fixture(scope="session")
def run_plant(plant_fmu):
    """run_plant(stop_time, output_interval, **start_values) -> RunResult."""

    def run(stop_time=200.0, output_interval=0.1, **start_values):
        return run_fmu(plant_fmu, start_values, stop_time, output_interval)

    return run
