"""Install an FMI 2.0 status shim into a pythonfmu-built FMU.

Why this exists -- pythonfmu 0.7.0 gives a Python slave no way to make an
FMI call return ``fmi2Error``:

* a ``do_step`` returning False makes ``fmi2DoStep`` return ``fmi2Discard``;
* the return value of ``exit_initialization_mode`` (and the other hooks) is
  ignored, the call always returns ``fmi2OK``;
* any Python exception becomes ``fmi2Fatal`` and pythonfmu's C++ layer
  (``handle_py_exception`` -> ``cleanPyObject``) releases the Python slave
  object while keeping the pointer, so any later call on that instance --
  including ``fmi2FreeInstance`` -- is a use-after-free that can crash the
  host.

The shim (``fmu_src/fmi2_status_shim.c``) is a small C library that becomes
``binaries/linux64/<modelIdentifier>.so``; pythonfmu's library is kept beside
it as ``<modelIdentifier>_pythonfmu.so`` and loaded at run time.  After each
state-changing call the shim reads an Integer status variable of the slave
(0 = ok, 3 = error) and turns the result into ``fmi2Error`` when it is 3.
After an ``fmi2Fatal`` it stops forwarding calls (and leaks the broken inner
instance rather than freeing it).  pythonfmu also drops every log message,
errors included, unless the host turned debug logging on; the shim therefore
runs it with logging on and itself passes warnings/errors/fatals to the host
always, fmi2OK messages only when logging is on.  See the C file for the
exact rules.
"""

from __future__ import annotations

import os
import subprocess
import tempfile
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

from vibrofmu import paths
from vibrofmu.fmus import toolchain

SHIM_SOURCE = paths.FMU_SRC / "fmi2_status_shim.c"
PYLOADER_SOURCE = SHIM_SOURCE.with_name("pyloader.c")  # finds the FMU's Python (see there)
FMI_DIR = paths.FMU_SRC / "fmi"  # the FMI 2.0 layer shared with the native FMUs, and the host-API header
LAYER_SOURCE = FMI_DIR / "fmi2_layer.c"


def _model_identifier_and_check_vr(model_description: bytes, status_vr: int) -> str:
    root = ET.fromstring(model_description)
    cs = root.find("CoSimulation")
    if cs is None or not cs.get("modelIdentifier"):
        raise ValueError("modelDescription.xml has no CoSimulation modelIdentifier")
    # A wrong value reference would make pythonfmu raise a Python KeyError on
    # every flag read, i.e. turn every call into fmi2Fatal: refuse it here.
    for sv in root.iter("ScalarVariable"):
        if sv.get("valueReference") == str(status_vr) and sv.find("Integer") is not None:
            return cs.get("modelIdentifier")
    raise ValueError(f"no Integer variable with valueReference {status_vr} in the FMU")


def _guid(model_description: bytes) -> str:
    """modelDescription.xml's guid, which fmi2Instantiate checks (compiled into the shim as a C string)."""
    guid = ET.fromstring(model_description).get("guid") or ""
    if not guid or any(c in guid for c in '"\\\n') or not guid.isascii():
        raise ValueError(f"modelDescription.xml's guid {guid!r} cannot be compiled into the shim")
    return guid


def _compile_shim(status_vr: int, out: Path, guid: str = "") -> None:
    cmd = [*toolchain.c_compiler(), *toolchain.SHIM, f"-DSTATUS_VR={int(status_vr)}", f'-DFMU_GUID="{guid}"',
           f"-I{FMI_DIR}",
           toolchain.fmi_include(), "-o", str(out), str(SHIM_SOURCE), str(LAYER_SOURCE), str(PYLOADER_SOURCE),
           *toolchain.SHIM_LIBS]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"compiling the status shim failed ({' '.join(cmd)}):\n{proc.stderr}")


IDENTITY = "resources/vibrofmu_identity.txt"


def identity(guid: str, module: str, names: list[str]) -> str:
    """The model's identity the shim checks in fmi2Instantiate (fmi2_status_shim.c, slave_files): its GUID (the
    binary's own: resources of another FMU are refused), its slave module (slavemodule.txt must name it), then every
    Python file of its resources, relative to the folder (a partial extraction that lost one is refused, instead of
    failing inside pythonfmu's import)."""
    files = sorted(name[len("resources/"):] for name in names
                   if name.startswith("resources/") and name.endswith(".py") and "/pythonfmu/" not in name)
    return "\n".join([guid, module, *files]) + "\n"


def install_status_shim(fmu_path: Path, status_vr: int) -> None:
    """Rewrite ``fmu_path`` in place so that linux64 uses the status shim.

    ``status_vr`` is the value reference of the slave's Integer status flag.
    Only linux64 gets the shim: the binaries of all other platforms (pythonfmu
    also packs a win64 dll) are dropped, so that no platform in the FMU keeps
    the old error semantics.  Running it again on a shimmed FMU replaces the
    shim and keeps the original pythonfmu library.
    """
    fmu_path = Path(fmu_path)
    with zipfile.ZipFile(fmu_path) as zin:
        model_id = _model_identifier_and_check_vr(zin.read("modelDescription.xml"), status_vr)
        names = zin.namelist()
        shim_name = f"binaries/linux64/{model_id}.so"
        inner_name = f"binaries/linux64/{model_id}_pythonfmu.so"
        original = inner_name if inner_name in names else shim_name
        if original not in names:
            raise ValueError(f"{fmu_path} has no {shim_name}")

        with tempfile.TemporaryDirectory() as tmp:
            shim_so = Path(tmp) / "shim.so"
            _compile_shim(status_vr, shim_so, _guid(zin.read("modelDescription.xml")))
            # read before the copy: writestr(info) rewrites zin's own entries (their offsets) for the output
            model_identity = identity(_guid(zin.read("modelDescription.xml")),
                                      zin.read("resources/slavemodule.txt").decode().strip(), names)
            fd, tmp_fmu = tempfile.mkstemp(suffix=".fmu", dir=fmu_path.parent)
            os.close(fd)
            try:
                with zipfile.ZipFile(tmp_fmu, "w", zipfile.ZIP_DEFLATED) as zout:
                    for info in zin.infolist():
                        if info.filename.startswith("binaries/") or info.filename == IDENTITY:
                            continue
                        zout.writestr(info, zin.read(info.filename))
                    zout.writestr(IDENTITY, model_identity)
                    zout.writestr(inner_name, zin.read(original))
                    zout.write(shim_so, shim_name)
                os.replace(tmp_fmu, fmu_path)
            except BaseException:
                Path(tmp_fmu).unlink(missing_ok=True)
                raise
