"""The fuzz targets' seed corpus and a replay of it (tests/fuzz/run.py fuzzes; CI runs it for 60 s)."""
import subprocess
import sys
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import run  # noqa: E402  (tests/fuzz/run.py)
import seeds  # noqa: E402  (tests/fuzz/seeds.py)


def test_seed_corpus_is_what_seeds_py_writes(tmp_path):
    """The committed corpus is seeds.py's output, file for file (a changed byte layout of the targets changes the
    seeds: rerun python3 tests/fuzz/seeds.py)."""
    seeds.write_all(tmp_path)
    written = {p.relative_to(tmp_path): p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()}
    committed = {p.relative_to(HERE / "corpus"): p.read_bytes() for p in (HERE / "corpus").rglob("*") if p.is_file()}
    assert written == committed
    assert {str(p.parent) for p in written} == set(run.targets())  # a seed folder for every target


@pytest.mark.tools("clang-14")
def test_layer_target_replays_its_seeds(tmp_path):
    """The FMI 2.0 layer's target (fuzz_layer.c on fmi2_layer.c, ASan + UBSan) builds and runs its seed corpus
    without a finding."""
    run.build(tmp_path, ["layer"])
    proc = subprocess.run([str(tmp_path / "bin" / "layer"), "-runs=0", str(HERE / "corpus" / "layer")],
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "Done" in proc.stderr or "DONE" in proc.stderr or "INITED" in proc.stderr, proc.stderr[-2000:]
