"""Programs outside Python and the C compiler that some tests need: mingw-w64 and wine (the win64 binaries), valgrind
(the C hosts under it), cmake (FMPy's build of an FMU's sources/), and one library's headers: SUNDIALS' CVODE (the
bench's CVODE peer, whose driver the warnings check compiles, and the Model Exchange C host
tests/c_host/fmi2_me_cvode.c). Such a test is marked `tools` with the programs it needs
(@pytest.mark.tools("valgrind")): the default run leaves the tier out and says so in one line (tests/conftest.py);
`python3 -m pytest -m tools` runs it, and a test whose program is missing fails with one line naming what to
install, it never skips itself (.ci/run installs them with apt-get when it runs as root)."""
import shutil
import subprocess

from vibrofmu.fmus import toolchain

# program -> the Debian packages that provide it
PACKAGES = {
    "x86_64-w64-mingw32-gcc": "gcc-mingw-w64-x86-64",
    "wine": "wine wine64",
    "valgrind": "valgrind",
    "cmake": "cmake",
    "cvode/cvode.h": "libsundials-dev",  # a header, found by the C compiler's preprocessor
    "clang-14": "clang-14 libclang-rt-14-dev libfuzzer-14-dev",  # tests/fuzz: libFuzzer with ASan + UBSan
}
WIN64 = ("x86_64-w64-mingw32-gcc", "wine")


def missing(programs) -> str | None:
    """None when every program is on PATH (and every header found by the C compiler), else one line naming the missing ones and what to install."""
    unknown = [program for program in programs if program not in PACKAGES]
    assert not unknown, f"tests/required_tools.py does not know {unknown}"
    absent = [program for program in programs if not _found(program)]
    if not absent:
        return None
    packages = " ".join(dict.fromkeys(PACKAGES[program] for program in absent))
    return (f"{' and '.join(absent)} not found (on PATH, or for a header by the C compiler): this test of the "
            f"`tools` tier needs it; install Debian's {packages} (apt-get install {packages}; .ci/run does when it "
            "runs as root)")


def _found(name: str) -> bool:
    if not name.endswith(".h"):
        return shutil.which(name) is not None
    proc = subprocess.run([*toolchain.c_compiler(), "-E", "-x", "c", "-"], input=f"#include <{name}>\n",
                          capture_output=True, text=True)
    return proc.returncode == 0
