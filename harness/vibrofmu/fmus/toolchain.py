"""The C toolchain, in one place: the compiler command, where the FMI standard's headers are, and the named flag
sets of every C build of the project (the compiled core, the status shim, the native FMUs for linux64 and win64,
the C hosts).

Every flag set warns with -Wall -Wextra; tests/fmus/test_c_toolchain.py compiles every C translation unit of the project
with these sets plus -Werror, so a new warning fails there. The flags that decide numbers stay exactly as they
were: the compiled core and the native FMUs compute in IEEE double arithmetic as written (-ffp-contract=off: no
FMA contraction, no -ffast-math), which is what makes them bit-identical to the Python model; their speed comes
from -O3 and -flto (-O3 reorders no floating-point operation: without -ffast-math GCC keeps every sum in its written
order, so -O2 and -O3 give the same bits; -O3 executes 8 % fewer instructions per paper run of the kernel).

The FMI 2.0 headers (fmi2Functions.h, fmi2FunctionTypes.h, fmi2TypesPlatform.h) are the standard's own, read from
FMPy's installed package (fmpy/c-code, FMPy's `build_platform_binary` compiles FMU sources against the same
folder): nothing of the standard is copied into this repository.
"""
from __future__ import annotations

import importlib.util
import os
import shlex
import shutil
from pathlib import Path

WARNINGS = ("-Wall", "-Wextra")
# IEEE double arithmetic as written (bit identity of the C core with the Python model): see the module's text.
IEEE = ("-ffp-contract=off",)

# The compiled core (fmu_src/core/*.c -> vibrokernel.so), one optimisation unit (-flto).
# -flto=auto: at -O3 the library is large enough for 2 LTRANS partitions, which plain -flto compiles serially with a
# warning (as the native FMUs' flags below).
KERNEL = ("-std=c11", "-O3", *IEEE, "-fPIC", "-shared", "-flto=auto", "-fno-semantic-interposition", *WARNINGS)
# What the kernel library exports: its API, the globals named KERNEL_PREFIX* (what the ctypes front ends, the FMU's
# fast path and the C drivers look up); every other global (the solvers' steps, brentq, bernstein_*, the models'
# functions) is local to the library, by this version script (kernel.compile_kernel passes it to the linker).
KERNEL_PREFIX = "vk_"
KERNEL_VERSION_SCRIPT = f"{{ global: {KERNEL_PREFIX}*; local: *; }};\n"
# The status shim over pythonfmu's library (fmu_src/fmi2_status_shim.c with fmi/fmi2_layer.c and pyloader.c).
SHIM = ("-shared", "-fPIC", "-O2", "-fvisibility=hidden", *WARNINGS)
SHIM_LIBS = ("-ldl", "-pthread")
# The native FMUs: the same arithmetic as the core; -flto across the model, solver and FMI files (=auto: the larger
# FMI 3.0 binaries are split into LTO partitions, compiled in parallel rather than with a warning).
NATIVE = ("-std=c11", "-O3", *IEEE, *WARNINGS)
NATIVE_LINUX64 = (*NATIVE, "-fPIC", "-shared", "-fvisibility=hidden", "-flto=auto")
# Debian's mingw-w64; __USE_MINGW_ANSI_STDIO: C99 printf (inf, %zu, %g as glibc) instead of msvcrt's.
# -flto=auto: its plain -flto splits the closed loop into 2 LTRANS jobs and, finding no jobserver, warns "using
# serial compilation" on stderr (a build that warns fails); =auto runs them side by side, silently.
WIN64_COMPILER = "x86_64-w64-mingw32-gcc"
NATIVE_WIN64 = (*NATIVE, "-shared", "-static-libgcc", "-D__USE_MINGW_ANSI_STDIO=1", "-flto=auto")
# The C hosts (tests/c_host/fmi2_host.c, instance_cycles.c, speed/timing_host.c, speed/floor_driver.c).
HOST = ("-O2", *WARNINGS)
HOST_LIBS = ("-ldl", "-lm")
HOST_WIN64 = ("-O2", *WARNINGS, "-D__USE_MINGW_ANSI_STDIO=1")


class RegistryNotBuildable(RuntimeError):
    """The fidelity registry cannot be built into C (kernel.check_fidelity_header): what is missing, in one line.
    Here, beside NoCompiler, so that the command line words both without importing the kernel's module."""


class NoCompiler(RuntimeError):
    """No C compiler: $CC is unset and neither cc nor gcc is on PATH, or $CC names no program."""


def c_compiler() -> list[str]:
    """The C compiler command: $CC (split like a shell word list, e.g. "ccache gcc"), else cc, else gcc.
    Raises NoCompiler when there is none."""
    command = shlex.split(os.environ.get("CC", ""))
    if command:
        if shutil.which(command[0]) is None:
            raise NoCompiler(f"$CC = {os.environ['CC']!r} is not a program on PATH")
        return command
    for name in ("cc", "gcc"):
        if shutil.which(name):
            return [name]
    raise NoCompiler("no C compiler: $CC is not set and neither cc nor gcc is on PATH")


def fmi_include_dir() -> Path:
    """The folder of the FMI standard's headers in FMPy's installed package (fmpy/c-code); FileNotFoundError when
    FMPy is missing or ships no fmi2Functions.h."""
    spec = importlib.util.find_spec("fmpy")
    if spec is None or spec.origin is None:
        raise FileNotFoundError("FMPy is not installed: the FMI 2.0 headers come from its package (pip install fmpy)")
    folder = Path(spec.origin).parent / "c-code"
    if not (folder / "fmi2Functions.h").is_file():
        raise FileNotFoundError(f"{folder} has no fmi2Functions.h (FMPy's FMI headers)")
    return folder


def fmi_include() -> str:
    """-I of the FMI standard's headers."""
    return f"-I{fmi_include_dir()}"


def host_includes() -> list[str]:
    """-I of the host-API header (fmu_src/fmi/fmi2_host_api.h, which every C host includes) and of the FMI headers."""
    from vibrofmu import paths

    return [f"-I{paths.FMU_SRC / 'fmi'}", fmi_include()]


def compile_host(source: Path, out: Path) -> Path:
    """Compile the C host `source` (an FMI host on fmi/fmi2_host_api.h) to the program `out`; RuntimeError with the
    command and the compiler's messages when that fails."""
    import subprocess

    cmd = [*c_compiler(), *HOST, *host_includes(), "-o", str(out), str(source), *HOST_LIBS]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"compiling {Path(source).name} failed ({' '.join(cmd)}):\n{proc.stderr}")
    return Path(out)
