"""The C toolchain (vibrofmu.fmus.toolchain) and what is written once in C: every C translation unit of the project
compiles without a warning under -Wall -Wextra (its own flag set, plus -Werror), so that a new warning fails here;
the C layer's state table (fmu_src/fmi/fmi2_calls.h) is the one generated from slave_support.CALLS; the host-API
header (fmu_src/fmi/fmi2_host_api.h) names a function an FMU binary lacks.

-fsyntax-only runs the front end's warnings (those of -Wall -Wextra are front-end warnings) without generating
code, so the whole check takes seconds. The native FMUs' files need their generated headers (variables.h from a
built pythonfmu FMU's modelDescription.xml, rules.h, reference.h): they are written as the build writes them
(native.write_sources), and compiled with the native build's own flags."""
import subprocess
import zipfile

import pytest

from vibrofmu import paths
from vibrofmu.fmus import fmi_calls, native, toolchain
from vibrofmu.speed import instructions, ladder, native_timing, peer_instructions, peers

FMU_SRC = paths.FMU_SRC
STRICT = ("-fsyntax-only", "-Werror")


def compile_errors(flags, includes, source, defines=()):
    cmd = [*toolchain.c_compiler(), *flags, *STRICT, *defines, *includes, str(source)]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    return proc.returncode, f"{' '.join(cmd)}\n{proc.stderr}"


def units():
    """(id, flags, includes, source, defines) of every C file outside the native FMUs."""
    fmi = [f"-I{FMU_SRC / 'fmi'}", toolchain.fmi_include()]
    core = [(f"core/{path.name}", toolchain.KERNEL, [f"-I{FMU_SRC / 'core'}"], path, ())
            for path in sorted((FMU_SRC / "core").glob("*.c"))]
    shim = [(path.name, toolchain.SHIM, [*fmi, f"-I{FMU_SRC}"], path, ("-DSTATUS_VR=0", '-DFMU_GUID="guid"'))
            for path in (FMU_SRC / "fmi2_status_shim.c", FMU_SRC / "pyloader.c", FMU_SRC / "fmi" / "fmi2_layer.c")]
    hosts = [(path.name, toolchain.HOST, toolchain.host_includes(), path, ())
             for path in (paths.C_HOST_DIR / "fmi2_host.c", paths.C_HOST_DIR / "instance_cycles.c",
                          ladder.TIMING_HOST_SOURCE, instructions.FLOOR_DRIVER_SOURCE,
                          native_timing.FMI_VERSIONS_HOST_SOURCE)]
    # numbalsoda's solvers on a C right-hand side, for the peers' instruction counts (speed/peer_instructions.py)
    hosts.append((peer_instructions.DRIVER_SOURCE.name, toolchain.HOST, [], peer_instructions.DRIVER_SOURCE, ()))
    # the CVODE peer's driver (bench --peers), on the core's model and the system's SUNDIALS headers (.ci/run)
    cvode = [(peers.CVODE_SOURCE.name, toolchain.HOST, [f"-I{FMU_SRC / 'core'}"], peers.CVODE_SOURCE, ()),
             # the Model Exchange host on CVODE (tests/fmus/test_controller_model_exchange.py)
             ("fmi2_me_cvode.c", toolchain.HOST, toolchain.host_includes(), paths.C_HOST_DIR / "fmi2_me_cvode.c", ())]
    return core + shim + hosts + cvode


def marked(unit):
    """The CVODE driver needs SUNDIALS' headers (Debian's libsundials-dev): the `tools` tier, not the default run."""
    needs_cvode = unit[3] in (peers.CVODE_SOURCE, paths.C_HOST_DIR / "fmi2_me_cvode.c")
    return pytest.param(unit, id=unit[0], marks=[pytest.mark.tools("cvode/cvode.h")] if needs_cvode else [])


def test_every_c_file_is_compiled_here():
    """The list above misses no C file of fmu_src/ (but the native models', below) nor of the C hosts."""
    listed = {unit[3].resolve() for unit in units()}
    native_files = set((FMU_SRC / "native").rglob("*.c")) | {FMU_SRC / "fmi" / "fmi2_layer.c"}
    every = {path.resolve() for path in FMU_SRC.rglob("*.c") if path not in native_files}
    every |= {path.resolve() for path in paths.C_HOST_DIR.glob("*.c")}
    every |= {path.resolve() for path in ladder.TIMING_HOST_SOURCE.parent.glob("*.c")}
    assert every - listed == set()


@pytest.mark.parametrize("unit", [marked(unit) for unit in units()])
def test_compiles_without_warnings(unit):
    _, flags, includes, source, defines = unit
    code, output = compile_errors(flags, includes, source, defines)
    assert code == 0, output


@pytest.mark.fmu
@pytest.mark.parametrize("fmi_version", (2, 3))
@pytest.mark.parametrize("which", ("plant", "controller", "closed_loop"))
def test_native_fmu_sources_compile_without_warnings(request, which, fmi_version, tmp_path):
    with zipfile.ZipFile(request.getfixturevalue(f"{which}_fmu")) as fmu:
        md = fmu.read("modelDescription.xml")
    model_id = {"plant": "HertzEAOscillator", "controller": "AdaptiveLyapunovController",
                "closed_loop": "HertzEAClosedLoop"}[which]
    c_files = native.write_sources(model_id, md, tmp_path, fmi_version)
    for name in c_files:
        code, output = compile_errors(toolchain.NATIVE_LINUX64, [f"-I{tmp_path}", toolchain.fmi_include()],
                                      tmp_path / name)
        assert code == 0, output


def test_a_warning_fails_the_check(tmp_path):
    """The check can fail: an unused variable (-Wall) and an unused parameter (-Wextra) are errors here."""
    for body in ("int f(void) { int unused; return 0; }", "int f(int unused) { return 0; }"):
        source = tmp_path / "warns.c"
        source.write_text(body + "\n")
        code, output = compile_errors(toolchain.HOST, [], source)
        assert code != 0 and "[-Werror=unused-" in output, output


def test_the_state_table_header_is_current():
    """fmu_src/fmi/fmi2_calls.h is what `python3 -m vibrofmu.fmus.fmi_calls` writes from slave_support.CALLS."""
    assert fmi_calls.CALLS_HEADER.read_text() == fmi_calls.calls_header()


def test_the_c_host_names_a_function_the_library_lacks(tmp_path):
    """fmi2_host_api.h's fmi2_api_missing in the C host: a library with every function the host calls but
    fmi2DoStep is refused before anything is called, naming fmi2DoStep's short name (exit code 1)."""
    from vibrofmu.hosts.doctor import compile_host

    source = tmp_path / "partial.c"
    source.write_text("\n".join(
        ['#include "fmi2Functions.h"',
         "fmi2Component fmi2Instantiate(fmi2String a, fmi2Type b, fmi2String c, fmi2String d,",
         "    const fmi2CallbackFunctions *e, fmi2Boolean f, fmi2Boolean g)",
         "{ (void)a; (void)b; (void)c; (void)d; (void)e; (void)f; (void)g; return 0; }",
         *(f"fmi2Status fmi2{name}(fmi2Component c) {{ (void)c; return fmi2OK; }}"
           for name in ("EnterInitializationMode", "ExitInitializationMode", "Terminate")),
         "void fmi2FreeInstance(fmi2Component c) { (void)c; }",
         "fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean a, fmi2Real b, fmi2Real d, fmi2Boolean e,",
         "    fmi2Real f) { (void)c; (void)a; (void)b; (void)d; (void)e; (void)f; return fmi2OK; }",
         "fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference v[], size_t n, fmi2Real x[])",
         "{ (void)c; (void)v; (void)n; (void)x; return fmi2OK; }",
         "fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference v[], size_t n, const fmi2Real x[])",
         "{ (void)c; (void)v; (void)n; (void)x; return fmi2OK; }", ""]))
    library = tmp_path / "partial.so"
    subprocess.run([*toolchain.c_compiler(), "-shared", "-fPIC", *toolchain.WARNINGS, "-Werror",
                    toolchain.fmi_include(), "-o", str(library), str(source)], check=True, capture_output=True)
    host = compile_host(tmp_path)
    proc = subprocess.run([str(host), str(library), "file:///nowhere", "guid", "0", "1", "0.5", "0"],
                          capture_output=True, text=True, env={})
    assert proc.returncode == 1 and "missing FMI function: DoStep" in proc.stderr, proc.stderr
    assert proc.stdout == ""  # refused before fmi2Instantiate: nothing simulated
