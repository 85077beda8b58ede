"""Build the FMUs: pythonfmu packs the slave, slave_support, fast_path and the vibromodel package; the status shim
goes on top; the plant also gets the compiled kernel (vibrokernel.so) in its resources; the reference result of
the default experiment goes into the documentation."""
from __future__ import annotations

import tempfile
from pathlib import Path

import vibromodel
from fmpy import read_model_description
from pythonfmu import FmuBuilder
from vibromodel.analytic import OafmSettings, cached_solve, covering
from vibromodel.compiled import LIBRARY_NAME
from vibromodel.parameters import Scene
from vibromodel.plant import DEFAULT_EXPERIMENT

from .entry import importable, pythonfmu_entry
from .kernel import compile_kernel
from .refresult import pack_reference
from .shim import install_status_shim

FMU_SRC = Path(vibromodel.__file__).resolve().parents[1]
REPO_ROOT = FMU_SRC.parent
BUILD_DIR = REPO_ROOT / "build"
PLANT_SLAVE = FMU_SRC / "HertzEAOscillator.py"
CONTROLLER_SLAVE = FMU_SRC / "AdaptiveLyapunovController.py"
CLOSED_LOOP_SLAVE = FMU_SRC / "HertzEAClosedLoop.py"
PLANT_FMU = BUILD_DIR / "HertzEAOscillator.fmu"
CONTROLLER_FMU = BUILD_DIR / "AdaptiveLyapunovController.fmu"
CLOSED_LOOP_FMU = BUILD_DIR / "HertzEAClosedLoop.fmu"


def build_fmu(slave: Path, out_dir: Path = BUILD_DIR, extra_resources: tuple[Path, ...] = ()) -> Path:
    """Build out_dir/<slave name>.fmu with vibromodel, slave_support (and extra_resources) in its resources,
    the status shim installed and the reference result packed. It declares state save/restore and serialization:
    the slaves save their whole state (slave_support.StatusSlave; pythonfmu alone saves registered variables only)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp, importable(FMU_SRC):  # an entry script in front (vibrofmu.entry)
        entry, implementation = pythonfmu_entry(slave, Path(tmp))
        project_files = [FMU_SRC / "vibromodel", FMU_SRC / "slave_support.py", FMU_SRC / "fast_path.py",
                         implementation, *extra_resources]
        fmu = Path(FmuBuilder.build_FMU(entry, dest=out_dir, project_files=project_files,
                                        canGetAndSetFMUstate=True, canSerializeFMUstate=True))
    status = next(v for v in read_model_description(str(fmu)).modelVariables if v.name == "fmi_status")
    install_status_shim(fmu, status.valueReference)
    pack_reference(fmu)
    return fmu


def build_with_default_oafm(slave: Path, scene: Scene, out_dir: Path, extra_resources: tuple[Path, ...] = ()) -> Path:
    """Build with the OAFM solution of `scene` over the default experiment packed in resources/oafm_cache:
    an OAFM reference of that scene starts without a fit."""
    with tempfile.TemporaryDirectory() as tmp:
        cache = Path(tmp) / "oafm_cache"
        start, stop, _ = DEFAULT_EXPERIMENT
        cached_solve(scene, covering(scene, OafmSettings(), stop - start), start, write_dir=cache)
        return build_fmu(slave, out_dir, extra_resources=(cache, *extra_resources))


def build_plant(out_dir: Path = BUILD_DIR) -> Path:
    """The plant FMU with the compiled kernel; fidelity 4 of its default scene starts without a fit."""
    with tempfile.TemporaryDirectory() as tmp:
        kernel = compile_kernel(Path(tmp) / LIBRARY_NAME)
        return build_with_default_oafm(PLANT_SLAVE, Scene(), out_dir, extra_resources=(kernel,))


def build_controller(out_dir: Path = BUILD_DIR) -> Path:
    """The controller FMU with the compiled kernel (fmu_src/core/controller.c is in it)."""
    with tempfile.TemporaryDirectory() as tmp:
        return build_fmu(CONTROLLER_SLAVE, out_dir, extra_resources=(compile_kernel(Path(tmp) / LIBRARY_NAME),))


def build_closed_loop(out_dir: Path = BUILD_DIR) -> Path:
    """The monolithic closed loop with the compiled kernel (fmu_src/core/closedloop.c is in it); its OAFM reference
    (x~(0) = 0.04, x~'(0) = 0: the paper example) is packed."""
    with tempfile.TemporaryDirectory() as tmp:
        kernel = compile_kernel(Path(tmp) / LIBRARY_NAME)
        return build_with_default_oafm(CLOSED_LOOP_SLAVE, Scene(), out_dir, extra_resources=(kernel,))


def build_all(out_dir: Path = BUILD_DIR) -> list[Path]:
    return [build(out_dir) for build in (build_plant, build_controller, build_closed_loop)]
