"""Atomic builds: every FMU, SSP and container FMU is assembled in a staging folder inside its destination and moved
to its name when complete (vibrofmu.fmus.archive.staging/publish), so Ctrl-C during `vibrofmu build` leaves, under
each final name, the previous file or none -- never half of one; and the commands that build a missing default FMU
rebuild one an earlier, interrupted build left half-done (archive.finished) instead of using it.

    python3 tests/harness/test_interrupted_build.py [TRIALS] [OUT_DIR]   # one line per trial, then a summary
    pytest -m slow tests/harness/test_interrupted_build.py                # 3 trials

Each trial sends SIGINT to `vibrofmu build`'s process group (as Ctrl-C in a terminal: the compilers too) at a
random moment of an uninterrupted build's duration, into the same folder (so later trials start with the FMUs of
earlier ones), and checks: exit code 130 (or 0 when the build had already ended), every *.fmu under the folder has
the entries of the uninterrupted build's file of that name and loads and steps in FMPy, and no staging folder is
left. The exit latency is printed, not asserted (speed belongs to `vibrofmu bench`).
"""
from __future__ import annotations

import os
import random
import signal
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import pytest

from vibrofmu import paths
from vibrofmu.fmus import archive

ROOT = Path(__file__).resolve().parents[2]
ENV = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT / "harness"), str(ROOT / "fmu_src")])}
BUILD = [sys.executable, "-c", "import sys; from vibrofmu.cli import main; sys.exit(main())", "build", "--out-dir"]
# an interrupted build stops within a second on an idle machine; these bounds only catch a build that ignores
# SIGINT altogether (a loaded 2-core machine stretches the build itself to minutes)
BUILD_TIMEOUT_S = 1800
AFTER_SIGINT_TIMEOUT_S = 300


def _default_sigint():
    """SIGINT's default action in the child (a run started in the background inherits SIG_IGN)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _start(out: Path) -> subprocess.Popen:
    return subprocess.Popen([*BUILD, str(out)], env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True, preexec_fn=_default_sigint)


def entries(folder: Path) -> dict[str, set[str]]:
    """{path of each .fmu under folder, relative: its entry names} (a file that is no zip: an empty set)."""
    found = {}
    for fmu in sorted(folder.rglob("*.fmu")):
        try:
            with zipfile.ZipFile(fmu) as z:
                found[str(fmu.relative_to(folder))] = set(z.namelist())
        except zipfile.BadZipFile:
            found[str(fmu.relative_to(folder))] = set()
    return found


def reference_build(out: Path) -> tuple[dict[str, set[str]], float]:
    """An uninterrupted build into out: (its entries, its wall time [s])."""
    started = time.monotonic()
    proc = subprocess.run([*BUILD, str(out)], env=ENV, capture_output=True, text=True, timeout=BUILD_TIMEOUT_S)
    assert proc.returncode == 0, proc.stderr
    return entries(out), time.monotonic() - started


def steps(fmu: Path) -> str | None:
    """None when FMPy loads the FMU and steps it to tau = 1; else why not."""
    from fmpy import simulate_fmu

    try:
        result = simulate_fmu(str(fmu), stop_time=1.0, output_interval=0.5)
    except Exception as error:  # noqa: BLE001 -- reported, the trial fails
        return f"{type(error).__name__}: {error}"
    return None if len(result) == 3 else f"{len(result)} rows"


def trial(out: Path, delay: float, reference: dict[str, set[str]]) -> dict:
    process = _start(out)
    time.sleep(delay)
    sent = time.monotonic()
    with_pgid = process.poll() is None
    if with_pgid:
        os.killpg(process.pid, signal.SIGINT)
    try:
        _, err = process.communicate(timeout=AFTER_SIGINT_TIMEOUT_S)
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
    left = entries(out)
    wrong = sorted(name for name, names in left.items() if names != reference.get(name))
    unfinished = sorted(name for name in left if not archive.finished(out / name))
    broken = {name: why for name in sorted(left) if name not in wrong and (why := steps(out / name))}
    staging = sorted(str(p.relative_to(out)) for p in out.rglob(".building-*"))
    return {"delay_s": round(delay, 2), "code": process.returncode, "exit_s": round(time.monotonic() - sent, 2),
            "fmus": len(left), "of": len(reference), "wrong": wrong, "unfinished": unfinished, "broken": broken,
            "staging": staging, "traceback": "Traceback" in err, "stderr": err[-400:]}


def ok(result: dict) -> bool:
    complete = result["fmus"] == result["of"]
    return (result["code"] == 130 or (result["code"] == 0 and complete)) and not (
        result["wrong"] or result["unfinished"] or result["broken"] or result["staging"] or result["traceback"])


def campaign(trials: int, work: Path, seed: int) -> list[dict]:
    reference, duration = reference_build(work / "reference")
    rng = random.Random(seed)
    out = work / "interrupted"
    out.mkdir(parents=True, exist_ok=True)
    results = []
    for _ in range(trials):
        results.append(trial(out, rng.uniform(0.3, duration), reference))
        print({k: v for k, v in results[-1].items() if k != "stderr"}, flush=True)
    return results


@pytest.mark.slow  # an uninterrupted build and three interrupted ones: minutes
def test_ctrl_c_during_build_leaves_complete_fmus_or_none(tmp_path):
    results = campaign(3, tmp_path, seed=36)
    assert all(ok(r) for r in results), results
    assert any(r["code"] == 130 for r in results), results  # at least one SIGINT landed inside the build


# -- the pieces, without a build ------------------------------------------------------------------------------
def _zip(path: Path, normalized: bool) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("modelDescription.xml", "<fmiModelDescription/>")
    return archive.normalize_entries(path) if normalized else path


def test_staging_leaves_nothing_when_interrupted_and_publish_replaces(tmp_path):
    final = _zip(tmp_path / "A.fmu", normalized=True)
    before = final.read_bytes()
    with pytest.raises(KeyboardInterrupt):
        with archive.staging(tmp_path) as stage:
            (stage / "A.fmu").write_bytes(b"half")
            raise KeyboardInterrupt
    assert final.read_bytes() == before and sorted(p.name for p in tmp_path.iterdir()) == ["A.fmu"]
    with archive.staging(tmp_path) as stage:
        staged = _zip(stage / "A.fmu", normalized=True)
        archive.publish(staged, final)
    assert archive.finished(final) and sorted(p.name for p in tmp_path.iterdir()) == ["A.fmu"]


def test_finished_tells_a_half_built_archive(tmp_path):
    assert archive.finished(_zip(tmp_path / "done.fmu", normalized=True))
    assert not archive.finished(_zip(tmp_path / "raw.fmu", normalized=False))  # the builder's entries, 0600
    whole = (tmp_path / "done.fmu").read_bytes()
    (tmp_path / "cut.fmu").write_bytes(whole[: len(whole) // 2])
    assert not archive.finished(tmp_path / "cut.fmu")
    assert not archive.finished(tmp_path / "missing.fmu")


def _published(out_dir: Path, name: str) -> Path:
    """A build's last steps: normalized in a staging folder, then published (stamped) as out_dir/name."""
    with archive.staging(out_dir) as stage:
        return archive.publish(_zip(stage / name, normalized=True), Path(out_dir) / name)


def _fake_plant_builds(monkeypatch, build_dir: Path) -> list:
    """built_plant's collaborators replaced: build_plant publishes a stand-in FMU and records its folder in the list
    returned; build_dir is the default build folder."""
    from vibrofmu.commands import common
    from vibrofmu.fmus import build

    built = []

    def fake_build_plant(out_dir):
        built.append(out_dir)
        return _published(out_dir, common.PLANT_NAME)

    monkeypatch.setattr(build, "build_plant", fake_build_plant)
    monkeypatch.setattr(common, "say_compiled_parts", lambda natives=False: None)
    monkeypatch.setattr(common, "checked_fmu", lambda path, model=None, **checks: path)
    monkeypatch.setattr(common.paths, "build_dir", lambda: build_dir)
    return built


def test_a_half_built_default_fmu_is_rebuilt_not_used(tmp_path, monkeypatch, capsys):
    from vibrofmu.commands import common

    half = _zip(tmp_path / common.PLANT_NAME, normalized=False)
    named = _zip(tmp_path / "named" / "plant.fmu", normalized=False)  # not the default: the user named it
    built = _fake_plant_builds(monkeypatch, tmp_path)
    assert common.built_plant(named) == named and built == []  # used as it is
    assert common.built_plant(half) == half
    assert built == [tmp_path] and archive.finished(half)
    assert "is incomplete: an interrupted build" in capsys.readouterr().err
    common.built_plant(half)  # finished now: used as it is
    assert built == [tmp_path]


def test_a_default_plant_fmu_of_changed_sources_is_rebuilt(tmp_path, monkeypatch, capsys):
    """A default plant FMU built before a file of fmu_src/ changed (a stale build) is rebuilt; a cache file and an
    FMU the user named leave it as it is; the rebuilt one is used as it is."""
    from vibrofmu.commands import common

    sources = tmp_path / "fmu_src"
    for name in ("core/plant.c", "vibromodel/__pycache__/plant.cpython-311.pyc"):
        (sources / name).parent.mkdir(parents=True, exist_ok=True)
        (sources / name).write_text("")
    monkeypatch.setattr(paths, "FMU_SRC", sources)
    archive.sources_stamp.cache_clear()
    built = _fake_plant_builds(monkeypatch, tmp_path / "build")
    try:
        default = _published(tmp_path / "build", common.PLANT_NAME)
        built.append(tmp_path / "build")
        named = tmp_path / "named" / "plant.fmu"
        named.parent.mkdir()
        named.write_bytes(default.read_bytes())
        (sources / "vibromodel/__pycache__/plant.cpython-311.pyc").write_text("cache")  # not a source
        archive.sources_stamp.cache_clear()
        assert common.built_plant(default) == default and built == [tmp_path / "build"]
        (sources / "core/plant.c").write_text("double f(void) { return 2.0; }\n")
        archive.sources_stamp.cache_clear()
        assert common.built_plant(named) == named and len(built) == 1  # the user named it: used as it is
        assert common.built_plant(default) == default and len(built) == 2
        assert f"({default} was built from other sources)" in capsys.readouterr().err
        common.built_plant(default)  # rebuilt from these sources: used as it is
        assert len(built) == 2
    finally:
        archive.sources_stamp.cache_clear()


def test_publish_stamps_the_sources_and_current_tells_an_older_build(tmp_path, monkeypatch):
    """A finished archive of other sources (an older checkout's build/: its stamp differs, or it has none) is not
    current; publish gives the stamp of the sources as they are; a change of any source changes the stamp."""
    final = _published(tmp_path, "A.fmu")
    assert archive.stamp(final) == archive.sources_stamp() and archive.current(final)
    assert archive.finished(_zip(tmp_path / "old.fmu", normalized=True))
    assert not archive.current(tmp_path / "old.fmu")  # finished, no stamp: built before stamps or elsewhere
    source = tmp_path / "src"
    (source / "core").mkdir(parents=True)
    (source / "core" / "model.c").write_text("double f(void) { return 1.0; }\n")
    monkeypatch.setattr(paths, "FMU_SRC", source)
    archive.sources_stamp.cache_clear()
    try:
        before = archive.sources_stamp()
        (source / "core" / "model.c").write_text("double f(void) { return 2.0; }\n")
        archive.sources_stamp.cache_clear()
        assert archive.sources_stamp() != before and not archive.current(final)
    finally:
        archive.sources_stamp.cache_clear()


def test_a_default_fmu_of_other_sources_is_rebuilt_not_used(tmp_path, monkeypatch, capsys):
    """An FMU left by a build of an older checkout is rebuilt by the commands, with a note saying why (it may not
    even load against this vibromodel: `report` failed with an AttributeError on such a build/)."""
    from vibrofmu.commands import common
    from vibrofmu.fmus import build

    old = _zip(tmp_path / common.PLANT_NAME, normalized=True)  # finished, but no stamp of these sources
    built = []

    def fake_build_all(out_dir):
        built.append(out_dir)
        for name in (common.PLANT_NAME, common.CONTROLLER_NAME, common.CLOSED_LOOP_NAME):
            _published(out_dir, name)

    monkeypatch.setattr(build, "build_all", fake_build_all)
    monkeypatch.setattr(common, "say_compiled_parts", lambda natives=False: None)
    for name in (common.CONTROLLER_NAME, common.CLOSED_LOOP_NAME):
        _published(tmp_path, name)
    assert common.built_all(tmp_path) == tmp_path and built == [tmp_path]
    assert f"{old} was built from other sources" in capsys.readouterr().err
    common.built_all(tmp_path)  # all current now: used as they are
    assert built == [tmp_path] and archive.current(old)


if __name__ == "__main__":
    import tempfile

    count = int(sys.argv[1]) if len(sys.argv) > 1 else 20
    work = Path(sys.argv[2]) if len(sys.argv) > 2 else Path(tempfile.mkdtemp(prefix="vibrofmu-interrupted-build-"))
    results = campaign(count, work, seed=int(time.time()))
    interrupted = [r for r in results if r["code"] == 130]
    print(f"{len(results)} trials: {len(interrupted)} interrupted (exit 130), {len(results) - len(interrupted)} "
          f"finished first; {sum(ok(r) for r in results)} ok; FMUs left complete per trial "
          f"{[r['fmus'] for r in results]} of {results[0]['of']}; none wrong, unfinished or broken: "
          f"{not any(r['wrong'] or r['unfinished'] or r['broken'] for r in results)}; staging left: "
          f"{sum(bool(r['staging']) for r in results)}; exit after SIGINT max "
          f"{max((r['exit_s'] for r in interrupted), default=0):.2f} s (median "
          f"{sorted(r['exit_s'] for r in interrupted)[len(interrupted) // 2] if interrupted else 0:.2f} s)")
    sys.exit(0 if all(ok(r) for r in results) else 1)
