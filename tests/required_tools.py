"""Programs some tests need (valgrind, cmake): such a test fails with one line naming what to install, it never
skips itself (.ci/run installs them with apt-get when they are missing and it runs as root)."""
import shutil


def require(program: str, debian_package: str, why: str) -> None:
    assert shutil.which(program) is not None, (
        f"{program} not on PATH: {why}; install Debian's {debian_package} (apt-get install {debian_package}; "
        ".ci/run does when it runs as root)")
