"""Build the FMUs: pythonfmu packs the slave, slave_support, fast_path and the vibromodel package; the status shim
goes on top; each FMU also gets the compiled kernel (vibrokernel.so) in its resources; the reference result of
the default experiment goes into the documentation; finally every variable gets its description and unit
(fmu_variables.annotate), the file is made readable by all (0644) and so is each of its entries (archive.normalize_entries).

Without a C compiler (toolchain.c_compiler) the FMUs are built without their compiled parts: no kernel (the plant
integrates in Python, the same numbers, slower) and no status shim (pythonfmu's own binary: a failing call
returns fmi2Discard or fmi2Fatal instead of fmi2Error). `compiled_parts()` says which case applies.
"""
from __future__ import annotations

import functools
import os
import tempfile
from pathlib import Path

from fmpy import read_model_description
from pythonfmu import FmuBuilder
from vibromodel.analytic import OafmSettings, cached_solve, covering
from vibromodel.parameters import Scene
from vibromodel.plant import DEFAULT_EXPERIMENT

from vibrofmu import paths
from vibrofmu.fmus.archive import normalize_entries, publish, staging
from vibrofmu.fmus.entry import importable, pythonfmu_entry
from vibrofmu.fmus.fmu_variables import annotate
from vibrofmu.fmus.kernel import check_fidelity_header, kernel_file
from vibrofmu.fmus.pythonenv import pack_python_env
from vibrofmu.fmus.refresult import pack_reference
from vibrofmu.fmus.shim import install_status_shim
from vibrofmu.fmus import compilers, toolchain

FMU_SRC = paths.FMU_SRC
PLANT_SLAVE = FMU_SRC / "HertzEAOscillator.py"
CONTROLLER_SLAVE = FMU_SRC / "AdaptiveLyapunovController.py"
CLOSED_LOOP_SLAVE = FMU_SRC / "HertzEAClosedLoop.py"
# File names of the FMUs; they are written to paths.build_dir() (./build) unless an out_dir is given.
PLANT_FMU = Path("HertzEAOscillator.fmu")
CONTROLLER_FMU = Path("AdaptiveLyapunovController.fmu")
CLOSED_LOOP_FMU = Path("HertzEAClosedLoop.fmu")
FMU_MODE = 0o644  # rw-r--r--: the FMU is a deliverable others read (mkstemp alone would leave 0600)


def compiled_parts() -> str | None:
    """None when a C compiler is available; else the one line that says what the FMUs are built without."""
    try:
        toolchain.c_compiler()
        return None
    except toolchain.NoCompiler as error:
        return (f"warning: {error}; building the FMUs without their compiled parts (no C kernel: the plant "
                f"integrates in Python, slower; no status shim: failures return fmi2Discard/fmi2Fatal, not fmi2Error)")


def win64_skipped() -> str | None:
    """None when the native FMUs get their win64 binaries; else the one line that says why they do not."""
    from vibrofmu.fmus.native import win64_available

    if compiled_parts() is not None or win64_available():
        return None  # no native FMUs at all (compiled_parts says so), or win64 is built
    return (f"warning: {toolchain.WIN64_COMPILER} is not on PATH: the native FMUs are built without win64 binaries "
            "(linux64 only; apt-get install gcc-mingw-w64-x86-64 adds them)")


def build_fmu(slave: Path, out_dir: Path | None = None, extra_resources: tuple[Path, ...] = ()) -> Path:
    """Build out_dir/<slave name>.fmu with vibromodel, slave_support (and extra_resources) in its resources,
    the status shim installed and the reference result packed. It declares state save/restore and serialization:
    the slaves save their whole state (slave_support.StatusSlave; pythonfmu alone saves registered variables only)."""
    out_dir = Path(out_dir) if out_dir is not None else paths.build_dir()
    # assembled in a staging folder in out_dir, moved to its name when complete (archive.staging: an interrupted
    # build leaves the previous FMU or none)
    with staging(out_dir) as stage:
        with tempfile.TemporaryDirectory() as tmp, importable(FMU_SRC):  # an entry script in front (fmus.entry)
            entry, implementation = pythonfmu_entry(slave, Path(tmp))
            project_files = [paths.vibromodel_dir(), FMU_SRC / "slave_support.py", FMU_SRC / "fast_path.py",
                             implementation, *extra_resources]
            fmu = Path(FmuBuilder.build_FMU(entry, dest=stage, project_files=project_files,
                                            canGetAndSetFMUstate=True, canSerializeFMUstate=True))
        if compiled_parts() is None:
            status = next(v for v in read_model_description(str(fmu)).modelVariables if v.name == "fmi_status")
            install_status_shim(fmu, status.valueReference)
            pack_python_env(fmu)  # the Python the FMU finds in a C host (resources/python_env.txt; read by the shim)
        pack_reference(fmu)
        annotate(fmu)
        normalize_entries(fmu)  # pythonfmu's builder and zipfile.writestr leave entries 0600 without a file type
        os.chmod(fmu, FMU_MODE)
        return publish(fmu, out_dir / fmu.name)


def build_with_default_oafm(slave: Path, scene: Scene, out_dir: Path, extra_resources: tuple[Path, ...] = ()) -> Path:
    """Build with the OAFM solution of `scene` over the default experiment packed in resources/oafm_cache:
    an OAFM reference of that scene starts without a fit."""
    with tempfile.TemporaryDirectory() as tmp:
        cache = Path(tmp) / "oafm_cache"
        start, stop, _ = DEFAULT_EXPERIMENT
        cached_solve(scene, covering(scene, OafmSettings(), stop - start), start, write_dir=cache)
        return build_fmu(slave, out_dir, extra_resources=(cache, *extra_resources))


def build_plant(out_dir: Path | None = None) -> Path:
    """The plant FMU with the compiled kernel (when there is a C compiler); fidelity 4 of its default scene
    starts without a fit."""
    return build_with_default_oafm(PLANT_SLAVE, Scene(), out_dir, extra_resources=_kernel())


def build_controller(out_dir: Path | None = None) -> Path:
    """The controller FMU with the compiled kernel (fmu_src/core/controller.c is in it) when there is a C
    compiler."""
    return build_fmu(CONTROLLER_SLAVE, out_dir, extra_resources=_kernel())


def build_closed_loop(out_dir: Path | None = None) -> Path:
    """The monolithic closed loop with the compiled kernel (fmu_src/core/closedloop.c is in it) when there is a C
    compiler; its OAFM reference (x~(0) = 0.04, x~'(0) = 0: the paper example) is packed."""
    return build_with_default_oafm(CLOSED_LOOP_SLAVE, Scene(), out_dir, extra_resources=_kernel())


def _kernel() -> tuple[Path, ...]:
    """(the compiled kernel,), or () without a C compiler: kernel.kernel_file(), compiled once per source version
    and compiler (its cache) rather than once per FMU."""
    if compiled_parts():
        return ()
    check_fidelity_header()  # the registry against core/fidelity.h: a cached kernel does not say
    return (kernel_file(),)


def build_all(out_dir: Path | None = None, win64: bool | None = None) -> list[Path]:
    """The pythonfmu FMUs in out_dir (default ./build) and their native twins in out_dir/native (vibrofmu.fmus.native;
    win64 as build_native takes it)."""
    fmus = [build(out_dir) for build in (build_plant, build_controller, build_closed_loop)]
    return fmus + build_natives(fmus, Path(fmus[0]).parent / "native", win64)


def build_natives(fmus: list[Path], out_dir: Path, win64: bool | None = None) -> list[Path]:
    """The native FMU of each pythonfmu FMU that has a native model (fmu_src/native/<id>/), as FMI 2.0 in out_dir
    and as FMI 3.0 in out_dir/fmi3 (with win64 binaries: win64 None when mingw-w64 is installed, else as given);
    none without a C compiler."""
    from vibrofmu.fmus.native import NATIVE_SRC, build_native

    if compiled_parts() is not None:
        return []
    natives = [fmu for fmu in fmus if (NATIVE_SRC / Path(fmu).stem / "native_model.c").is_file()]
    steps = [functools.partial(build_native, fmu, out_dir, win64) for fmu in natives] + [
        functools.partial(build_native, fmu, Path(out_dir) / "fmi3", win64, fmi_version=3) for fmu in natives]
    return compilers.in_parallel(steps)  # one compiler per core; Ctrl-C or a failure stops them all
