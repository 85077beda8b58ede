"""Fixtures of the host tests: the C host (tests/c_host/fmi2_host.c) compiled and the plant FMU unpacked, once per
module."""
from pathlib import Path

import pytest
from fmpy import extract

from vibrofmu.hosts.doctor import compile_host


@pytest.fixture(scope="module")
def c_host(tmp_path_factory):
    return compile_host(tmp_path_factory.mktemp("c_host"))


@pytest.fixture(scope="module")
def unpacked(plant_fmu, tmp_path_factory):
    return Path(extract(str(plant_fmu), unzipdir=str(tmp_path_factory.mktemp("unpacked"))))
