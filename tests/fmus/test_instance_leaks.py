"""Instantiate/free cycles do not leak (issue 15, item 4), measured in a C host (tests/c_host/instance_cycles.c)
so that no Python host's wrappers are counted: the resident set size after a warm-up (interpreter, imports and
caches settled) and after the cycles. Before the entry module (vibrofmu.fmus.entry) a plant instance kept 36 KB and a
controller or closed-loop instance 23 KB (pythonfmu's findClass)."""
import re
import subprocess
from pathlib import Path

import pytest
from fmpy import extract, read_model_description

from vibrofmu.fmus import toolchain
from vibrofmu.hosts.doctor import host_environment

pytestmark = pytest.mark.fmu  # every test here asks for FMUs by name (request.getfixturevalue)

SOURCE = Path(__file__).resolve().parents[1] / "c_host" / "instance_cycles.c"
FMUS = ("plant", "controller", "closed_loop", "native_plant", "native_controller", "native_closed_loop")


@pytest.fixture(scope="module")
def cycles_host(tmp_path_factory):
    host = tmp_path_factory.mktemp("cycles") / "instance_cycles"
    subprocess.run([*toolchain.c_compiler(), *toolchain.HOST, "-Werror", *toolchain.host_includes(), "-o", str(host),
                    str(SOURCE), *toolchain.HOST_LIBS],
                   check=True, capture_output=True)
    return host


def rss_growth_kb(host, fmu, unzip_dir, cycles, warmup, run):
    """RSS growth (KB) over `cycles` instantiate(/initialise/step/terminate)/free cycles after `warmup` ones."""
    md = read_model_description(str(fmu))
    library = Path(unzip_dir) / "binaries" / "linux64" / f"{md.coSimulation.modelIdentifier}.so"
    command = [str(host), str(library), (Path(unzip_dir) / "resources").as_uri(), md.guid, str(cycles), str(warmup)]
    proc = subprocess.run(command + (["run"] if run else []), capture_output=True, text=True, timeout=1800,
                          env=host_environment(Path(unzip_dir) / "resources"))
    assert proc.returncode == 0, proc.stderr
    return int(re.search(r"growth_kb=(-?\d+)", proc.stdout).group(1))


@pytest.mark.parametrize("which", FMUS)
def test_instantiate_free_cycles_do_not_leak(request, cycles_host, which, tmp_path):
    """500 cycles below 2 MB (4 KB a cycle), where 23 to 36 KB a cycle leaked before (11.5 to 18 MB here). The
    bound leaves room for the allocator's first growth: measured after the fix, 0.7 to 1.4 MB over the first
    500 to 2,000 cycles, then flattening out (10,000 cycles with runs: 1.5 to 2.8 MB, the slow test below)."""
    fmu = request.getfixturevalue(f"{which}_fmu")
    unzip_dir = extract(str(fmu), str(tmp_path / "fmu"))
    assert rss_growth_kb(cycles_host, fmu, unzip_dir, 500, 100, run=False) < 2048


@pytest.mark.slow
@pytest.mark.parametrize("which", FMUS)
def test_ten_thousand_cycles_with_a_run_each_grow_less_than_5_mb(request, cycles_host, which, tmp_path, capsys):
    """The issue's acceptance: 10,000 cycles (each initialising, stepping 3 times and terminating) in a C host,
    RSS growth < 5 MB."""
    fmu = request.getfixturevalue(f"{which}_fmu")
    unzip_dir = extract(str(fmu), str(tmp_path / "fmu"))
    growth = rss_growth_kb(cycles_host, fmu, unzip_dir, 10_000, 200, run=True)
    with capsys.disabled():
        print(f"\n{which}: RSS growth over 10,000 instantiate/run/free cycles: {growth} KB")
    assert growth < 5 * 1024
