"""The kernel library exports its API alone: every global it defines is named toolchain.KERNEL_PREFIX* (a version
script makes the rest local), so its internal functions (the solvers' steps, brentq, bernstein_*) can neither
clash with a host's symbols nor be interposed by them. (nm: binutils, which gcc needs.)"""
import subprocess

from vibrofmu.fmus import kernel, toolchain
from vibromodel.compiled import LIBRARY_NAME


def test_the_kernel_exports_only_its_prefix():
    kernel.kernel_library()
    listing = subprocess.run(["nm", "-D", "--defined-only", str(kernel.library_folder() / LIBRARY_NAME)],
                             capture_output=True, text=True, check=True).stdout
    names = [line.split()[-1] for line in listing.splitlines() if line.strip()]
    assert "vk_do_step" in names and "vk_loop_do_step" in names and "vk_controller_do_step" in names
    assert [name for name in names if not name.startswith(toolchain.KERNEL_PREFIX)] == []
