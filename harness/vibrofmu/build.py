"""Build the FMUs: pythonfmu packs the slave and the vibromodel package; the status shim goes on top;
the reference result of the default experiment goes into the documentation."""
from __future__ import annotations

import tempfile
from pathlib import Path

import vibromodel
from fmpy import read_model_description
from pythonfmu import FmuBuilder
from vibromodel.analytic import OafmSettings, cached_solve, covering
from vibromodel.parameters import Scene
from vibromodel.plant import DEFAULT_EXPERIMENT

from .refresult import pack_reference
from .shim import install_status_shim

FMU_SRC = Path(vibromodel.__file__).resolve().parents[1]
REPO_ROOT = FMU_SRC.parent
BUILD_DIR = REPO_ROOT / "build"
PLANT_SLAVE = FMU_SRC / "HertzEAOscillator.py"
PLANT_FMU = BUILD_DIR / "HertzEAOscillator.fmu"


def build_fmu(slave: Path, out_dir: Path = BUILD_DIR, extra_resources: tuple[Path, ...] = ()) -> Path:
    """Build out_dir/<slave name>.fmu with vibromodel (and extra_resources) in its resources, FMU state
    save/restore and serialization declared, the status shim installed and the reference result packed."""
    out_dir.mkdir(parents=True, exist_ok=True)
    fmu = Path(FmuBuilder.build_FMU(slave, dest=out_dir, project_files=[FMU_SRC / "vibromodel", *extra_resources],
                                    canGetAndSetFMUstate=True, canSerializeFMUstate=True))
    status = next(v for v in read_model_description(str(fmu)).modelVariables if v.name == "fmi_status")
    install_status_shim(fmu, status.valueReference)
    pack_reference(fmu)
    return fmu


def build_plant(out_dir: Path = BUILD_DIR) -> Path:
    """The plant FMU, with the OAFM solution of its default scene and experiment packed in
    resources/oafm_cache: fidelity 4 starts without a fit there."""
    with tempfile.TemporaryDirectory() as tmp:
        cache = Path(tmp) / "oafm_cache"
        start, stop, _ = DEFAULT_EXPERIMENT
        scene = Scene()
        cached_solve(scene, covering(scene, OafmSettings(), stop - start), start, write_dir=cache)
        return build_fmu(PLANT_SLAVE, out_dir, extra_resources=(cache,))
