"""Shared fixtures: the FMUs (pythonfmu and native) and the compiled kernel are built once per test session,
also under pytest-xdist: the first worker that needs one builds it into a folder all workers share (the
session's base temporary folder), under a file lock; the others wait for the lock and reuse it.

OAFM solutions fitted during the tests go to a fresh cache folder of this process, never the user's cache; only
the kernel's folder in it is shared between the workers (a link to the shared folder).
"""
import atexit
import os
import shutil
import tempfile
from pathlib import Path

import pytest
import required_tools

os.environ["VIBROFMU_CACHE_DIR"] = tempfile.mkdtemp(prefix="vibrofmu-test-cache-")

from vibrofmu.fmus import kernel
from vibrofmu.fmus.build import build_closed_loop, build_controller, build_plant
from vibrofmu.hosts.run import run_fmu

# VIBROFMU_CACHE_DIR (above): removed when this process (the run, or an xdist worker) exits: 1,633 of them were left in /tmp by earlier runs
atexit.register(shutil.rmtree, os.environ["VIBROFMU_CACHE_DIR"], ignore_errors=True)


# VIBROFMU_TEST_BUILDS=FOLDER (set by .ci/run for its two pytest runs): the FMUs and the kernel are built into
# FOLDER/<digest>/ instead of the run's temporary folder, so that a second run of the same tree (CI's `tools` tier
# after the default suite) reuses them rather than building them again. The digest covers every file the builds
# read (fmu_src/ and the harness, which holds the builders and the native C sources' generators) and the Python
# that runs them: a change of either is a new folder, never a stale FMU. Unset (a user's run): a fresh build.
BUILDS_ENV = "VIBROFMU_TEST_BUILDS"


def builds_digest() -> str:
    import hashlib
    import sys

    from vibrofmu.paths import FMU_SRC, PACKAGE_DIR

    digest = hashlib.sha256(f"{sys.executable}\0{sys.version}\0{os.environ.get('CC', '')}".encode())
    for root in (FMU_SRC, PACKAGE_DIR):
        for path in sorted(root.rglob("*")):
            if path.is_file() and "__pycache__" not in path.parts:
                digest.update(f"\0{path.relative_to(root.parent)}\0".encode() + path.read_bytes())
    return digest.hexdigest()[:16]


@pytest.fixture(scope="session")
def shared_dir(tmp_path_factory) -> Path:
    """A folder every process of this test run sees: VIBROFMU_TEST_BUILDS/<digest>/ when set (above), else the
    master's base temporary folder under pytest-xdist (each worker's own is a sub-folder of it), else this
    session's."""
    if os.environ.get(BUILDS_ENV):
        folder = Path(os.environ[BUILDS_ENV]) / builds_digest()
        folder.mkdir(parents=True, exist_ok=True)
        return folder
    base = tmp_path_factory.getbasetemp()
    return base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base


exclusive = kernel.exclusive  # one process at a time across the xdist workers (fcntl.flock)


def built_once(shared_dir: Path, name: str, build) -> Path:
    """build() -> path, called by the first process of the test run that asks for `name`; the others wait for it
    and get the same path. A build that raised is retried by the next process (its marker is never written)."""
    done = shared_dir / f"{name}.built"
    with exclusive(shared_dir / f"{name}.lock"):
        if done.exists():
            return Path(done.read_text())
        path = Path(build())
        done.write_text(str(path))
        return path


@pytest.fixture(scope="session", autouse=True)
def shared_kernel_folder(shared_dir):
    """Points this process's kernel cache (kernel.library_folder(), in the fresh cache folder above) at one folder
    shared by the workers, so that the kernel is compiled once per test run; kernel.kernel_library() compiles it
    under that folder's lock when a test first asks for it (nothing is compiled here)."""
    folder = kernel.library_folder()
    shared = shared_dir / folder.name
    shared.mkdir(exist_ok=True)
    folder.parent.mkdir(parents=True, exist_ok=True)
    if not folder.exists():
        folder.symlink_to(shared, target_is_directory=True)
    return shared


def fmu_dir(shared_dir: Path) -> Path:
    """The folder of the three pythonfmu FMUs (some tests pass it as --fmu-dir)."""
    folder = shared_dir / "fmu"
    folder.mkdir(exist_ok=True)
    return folder


@pytest.fixture(scope="session")
def plant_fmu(shared_dir):
    return built_once(shared_dir, "plant", lambda: build_plant(fmu_dir(shared_dir)))


@pytest.fixture(scope="session")
def controller_fmu(plant_fmu, shared_dir):
    return built_once(shared_dir, "controller", lambda: build_controller(plant_fmu.parent))


@pytest.fixture(scope="session")
def closed_loop_fmu(plant_fmu, shared_dir):
    return built_once(shared_dir, "closed_loop", lambda: build_closed_loop(plant_fmu.parent))


@pytest.fixture(scope="session")
def run_plant(plant_fmu):
    """run_plant(stop_time, output_interval, **start_values) -> RunResult."""

    def run(stop_time=200.0, output_interval=0.1, **start_values):
        return run_fmu(plant_fmu, start_values, stop_time, output_interval)

    return run


def _unzipped_fixture(name):
    """<name>_unzipped: the FMU extracted once, for tests that make many instances in this process."""

    @pytest.fixture(scope="session", name=f"{name}_unzipped")
    def unzipped(request, tmp_path_factory):
        from fmpy import extract

        return extract(str(request.getfixturevalue(f"{name}_fmu")), str(tmp_path_factory.mktemp(f"{name}_unzipped")))

    return unzipped


def _starter_fixture(name):
    """start_<name>: start(stop_time=None, **start_values) -> FmuInstance in step mode at tau = 0 (the caller
    closes it); raises FMICallException if initialisation fails."""

    @pytest.fixture(scope="session", name=f"start_{name}")
    def starter(request):
        from vibrofmu.hosts.run import FmuInstance

        fmu, unzipped = request.getfixturevalue(f"{name}_fmu"), request.getfixturevalue(f"{name}_unzipped")

        def start(stop_time=None, **start_values):
            instance = FmuInstance(fmu, unzip_dir=unzipped)
            instance.fmu.setupExperiment(startTime=0.0, stopTime=stop_time)
            instance.fmu.enterInitializationMode()
            instance.set(start_values)
            instance.fmu.exitInitializationMode()
            return instance

        return start

    return starter


def _native_fixture(name):
    """native_<name>_fmu: the native FMU (fmu_src/native/) built once per test run from the pythonfmu one (shared
    by tests/fmus/test_native.py, test_fuzz.py and test_nonfinite_outputs.py)."""

    @pytest.fixture(scope="session", name=f"native_{name}_fmu")
    def native(request, shared_dir):
        from vibrofmu.fmus.native import build_native

        pythonfmu, folder = request.getfixturevalue(f"{name}_fmu"), shared_dir / f"native_{name}"
        return built_once(shared_dir, f"native_{name}", lambda: build_native(pythonfmu, folder))

    return native


def _fmi3_fixture(name):
    """<name>_fmi3: the native FMU as FMI 3.0 (build_native(..., fmi_version=3)), built once per test run (shared
    by the FMI 3.0 tests of tests/fmus/: one build each instead of one per module)."""

    @pytest.fixture(scope="session", name=f"{name}_fmi3")
    def fmi3(request, shared_dir):
        from vibrofmu.fmus.native import build_native

        pythonfmu, folder = request.getfixturevalue(f"{name}_fmu"), shared_dir / f"fmi3_{name}"
        return built_once(shared_dir, f"fmi3_{name}", lambda: build_native(pythonfmu, folder, fmi_version=3))

    return fmi3


FMU_NAMES = ("plant", "controller", "closed_loop")
native_plant_fmu, native_controller_fmu, native_closed_loop_fmu = map(_native_fixture, FMU_NAMES)
plant_fmi3, controller_fmi3, closed_loop_fmi3 = map(_fmi3_fixture, FMU_NAMES)
NATIVE_NAMES = tuple(f"native_{name}" for name in FMU_NAMES)
native_plant_unzipped, native_controller_unzipped, native_closed_loop_unzipped = map(_unzipped_fixture, NATIVE_NAMES)
start_native_plant, start_native_controller, start_native_closed_loop = map(_starter_fixture, NATIVE_NAMES)
plant_unzipped, controller_unzipped, closed_loop_unzipped = map(_unzipped_fixture, FMU_NAMES)
start_plant, start_controller, start_closed_loop = map(_starter_fixture, FMU_NAMES)


# The tiers. A test that needs a built FMU is marked `fmu`: automatically when it uses an FMU fixture (directly or
# through other fixtures: item.fixturenames is the closure), by hand (@pytest.mark.fmu) when it asks for one with
# request.getfixturevalue or builds FMUs itself; a test that asks for an FMU fixture without the mark fails at
# set-up (FmuTierGuard), so that the fast tier cannot start building one. A test that takes seconds without an
# FMU (a study, a Dask cluster, a subprocess per case, a compile) is marked `long` by hand. Every other test not
# marked `slow` is marked `fast`: `pytest -m fast -n 2` is the tier that builds no FMU (under a minute).
# start_<name> and <name>_unzipped ask for <name>_fmu with getfixturevalue: not in the closure, so listed too.
FMU_FIXTURES = {f"{prefix}{name}{suffix}" for name in (*FMU_NAMES, *NATIVE_NAMES)
                for prefix, suffix in (("", "_fmu"), ("", "_unzipped"), ("start_", ""))} | {
                   f"{name}_fmi3" for name in FMU_NAMES}


def pytest_collection_modifyitems(config, items):
    for item in items:
        if FMU_FIXTURES & set(getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.fmu)
        if not any(item.get_closest_marker(name) for name in ("fmu", "long", "slow", "tools")):
            item.add_marker(pytest.mark.fast)


def _unmarked(item, names) -> None:
    if names and item.get_closest_marker("fmu") is None:
        raise pytest.UsageError(f"{item.nodeid} asks for {', '.join(sorted(names))} but is not marked fmu: add "
                                f"@pytest.mark.fmu (tests/conftest.py, the tiers)")


class FmuTierGuard:
    """Fails a test that asks for an FMU fixture without the fmu mark: when the fixture is set up (so that the
    fast tier builds nothing), and after the test's call, from every fixture it asked for, set up now or cached
    earlier (so that a full run fails the same way). A plugin, not conftest hooks: those are not called for the
    set-up of session fixtures."""

    @pytest.hookimpl(tryfirst=True)
    def pytest_fixture_setup(self, fixturedef, request):
        item = getattr(request, "_pyfuncitem", None)
        if item is not None and fixturedef.argname in FMU_FIXTURES:
            _unmarked(item, {fixturedef.argname})

    @pytest.hookimpl(trylast=True)  # after pytest's own, which runs the test (and stops here if it failed)
    def pytest_runtest_call(self, item):
        _unmarked(item, FMU_FIXTURES & set(getattr(getattr(item, "_request", None), "_fixture_defs", ())))


# The `tools` tier: tests that need a program beyond Python and the C compiler (@pytest.mark.tools("valgrind"),
# tests/required_tools.py). The default run (pyproject.toml's addopts) leaves them out and ends with one line saying
# how many and how to run them; `python3 -m pytest -m tools` runs them, and a missing program fails the test at
# set-up with one line naming what to install (never a skip). Under pytest-xdist the workers collect and deselect:
# each sends its count to the master (workeroutput), which prints the line.
TOOLS_RUN = "python3 -m pytest -m tools"


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_setup(item):
    marks = list(item.iter_markers("tools"))
    if marks:
        line = required_tools.missing([program for mark in marks for program in mark.args])
        if line:
            pytest.fail(line, pytrace=False)


class ToolsLeftOut:
    def __init__(self, config):
        self.config, self.count, self.programs = config, 0, set()

    def pytest_deselected(self, items):
        for item in items:
            marks = list(item.iter_markers("tools"))
            if marks:
                self.count += 1
                self.programs.update(program for mark in marks for program in mark.args)

    def pytest_sessionfinish(self):
        if hasattr(self.config, "workeroutput"):  # an xdist worker: tell the master
            self.config.workeroutput["tools_left_out"] = (self.count, sorted(self.programs))

    @pytest.hookimpl(optionalhook=True)
    def pytest_testnodedown(self, node, error):  # the xdist master: every worker collected the same tests
        count, programs = getattr(node, "workeroutput", {}).get("tools_left_out", (0, []))
        self.count = max(self.count, count)
        self.programs.update(programs)

    def pytest_terminal_summary(self, terminalreporter):
        if self.count and not hasattr(self.config, "workeroutput"):
            names = ", ".join(sorted(self.programs))
            tests = f"{self.count} test{'s' * (self.count != 1)}"
            terminalreporter.write_line(f"left out: {tests} of the `tools` tier (they need {names}); "
                                        f"run them with `{TOOLS_RUN}`")


def pytest_configure(config):
    config.pluginmanager.register(FmuTierGuard(), "vibrofmu-fmu-tier-guard")
    config.pluginmanager.register(ToolsLeftOut(config), "vibrofmu-tools-left-out")
