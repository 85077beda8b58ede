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


def test_merged_corpus_is_well_formed():
    """tests/fuzz/merged/ (run.py --merge: a campaign's corpus, minimized) holds one <target>.hex per target, each
    line an input in hex no longer than the longest input the runs allow (-max_len=512), none of them a seed."""
    packed = sorted((HERE / "merged").iterdir())
    assert [p.name for p in packed] == sorted(f"{t}.hex" for t in run.targets())
    for p in packed:
        inputs = [bytes.fromhex(line) for line in p.read_text().split()]
        seeds = {s.read_bytes() for s in (HERE / "corpus" / p.stem).iterdir()}
        assert all(len(data) <= 512 for data in inputs), p.name
        assert not seeds & set(inputs), p.name
        assert len(set(inputs)) == len(inputs), p.name


@pytest.mark.tools("clang-14")
def test_layer_target_replays_its_seeds(tmp_path):
    """The FMI 2.0 layer's target (fuzz_layer.c on fmi2_layer.c, ASan + UBSan) builds and runs its seed corpus
    and its merged campaign corpus without a finding."""
    run.build(tmp_path, ["layer"])
    merged = run.unpack_merged(tmp_path, "layer")
    assert merged is not None and any(merged.iterdir())
    proc = subprocess.run([str(tmp_path / "bin" / "layer"), "-runs=0", str(HERE / "corpus" / "layer"), str(merged)],
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "Done" in proc.stderr or "DONE" in proc.stderr or "INITED" in proc.stderr, proc.stderr[-2000:]
