"""Every output of two builds of the FMUs compared bit for bit on the paper scene.

`python -m vibrofmu.analyses.bit_identity OLD_DIR NEW_DIR` runs each FMU found in both folders (`vibrofmu build
--out-dir DIR`: the pythonfmu FMUs, DIR/native and DIR/native/fmi3) in every interface it offers (Co-Simulation,
Model Exchange) with its default start values (the paper scene) over [0, 200], output interval 0.1 (Model Exchange:
FMPy's CVode with fixed settings), and prints one row per FMU and interface: `identical`, or the outputs that
differ (first time, largest difference), are new, or are gone. A row says what differs, not why: that is for
whoever reads it. Exit status 0 when every output present in both is identical, 1 otherwise.
"""
from __future__ import annotations

import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path
from xml.etree import ElementTree

import numpy as np

STOP_TIME = 200.0
OUTPUT_INTERVAL = 0.1
ME_SOLVER = {"solver": "CVode", "relative_tolerance": 1e-6}  # the same fixed settings for the old and the new FMU


def interfaces(fmu: Path) -> tuple[list[str], list[str]]:
    """(the FMU's interfaces as FMPy names them, its output variables' names) from its modelDescription.xml."""
    with zipfile.ZipFile(fmu) as archive:
        root = ElementTree.fromstring(archive.read("modelDescription.xml"))
    kinds = [kind for kind in ("CoSimulation", "ModelExchange") if root.find(kind) is not None]
    variables = root.find("ModelVariables")
    outputs = [v.get("name") for v in (variables if variables is not None else []) if v.get("causality") == "output"]
    return kinds, outputs


def run(fmu: Path, kind: str, outputs: list[str]) -> dict[str, np.ndarray]:
    """Each output's values at the output times (and "time") of one run of fmu in interface kind, in a process
    of its own: two FMUs of one model identifier share a library name, and the dynamic loader would hand the
    second run the library the first one loaded."""
    with tempfile.TemporaryDirectory() as tmp:
        saved = Path(tmp) / "run.npz"
        subprocess.run([sys.executable, "-m", __name__ if __name__ != "__main__" else "vibrofmu.analyses.bit_identity",
                        "--run", str(fmu), kind, str(saved), *outputs], check=True)
        with np.load(saved) as data:
            return {name: data[name] for name in data.files}


def run_here(fmu: str, kind: str, saved: str, outputs: list[str]) -> None:
    """run's worker: one run of fmu saved to saved (.npz, one array per column)."""
    from fmpy import simulate_fmu

    extra = ME_SOLVER if kind == "ModelExchange" else {}
    result = simulate_fmu(fmu, fmi_type=kind, stop_time=STOP_TIME, output_interval=OUTPUT_INTERVAL,
                          output=outputs, **extra)
    np.savez(saved, **{name: np.asarray(result[name], dtype=float) for name in result.dtype.names})


def same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    """a and b hold the same doubles bit for bit (NaN and -0.0 included)."""
    return a.shape == b.shape and bool(np.array_equal(a.view(np.uint64), b.view(np.uint64)))


def compare(old: dict[str, np.ndarray], new: dict[str, np.ndarray]) -> list[str]:
    """One phrase per difference between two runs' columns; [] when every shared column is identical."""
    notes = [f"new output {name}" for name in new if name not in old]
    notes += [f"output {name} gone" for name in old if name not in new]
    times = old.get("time")
    for name in (n for n in old if n in new):
        a, b = old[name], new[name]
        if same_bits(a, b):
            continue
        if a.shape != b.shape:
            notes.append(f"{name}: {a.size} vs {b.size} points")
            continue
        differs = np.flatnonzero(a.view(np.uint64) != b.view(np.uint64))
        first = differs[0]
        at = f"t = {times[first]:g}" if times is not None else f"point {first}"
        largest = float(np.nanmax(np.abs(a[differs] - b[differs]))) if np.isfinite(a[differs] - b[differs]).any() else float("nan")
        notes.append(f"{name}: {differs.size} points differ from {at} (old {a[first]!r}, new {b[first]!r}), "
                     f"largest difference {largest:.3g}")
    return notes


def fmus(folder: Path) -> list[Path]:
    """The FMUs below folder, as paths relative to it."""
    return sorted(path.relative_to(folder) for path in Path(folder).rglob("*.fmu"))


def table(old_dir: Path, new_dir: Path) -> list[tuple[str, str, list[str]]]:
    """(FMU, interface, differences) for every FMU and interface in both folders; a missing one is a row too."""
    rows = []
    old_fmus, new_fmus = fmus(old_dir), fmus(new_dir)
    for name in sorted(set(old_fmus) | set(new_fmus)):
        if name not in old_fmus or name not in new_fmus:
            rows.append((str(name), "-", ["only in " + ("new" if name in new_fmus else "old")]))
            continue
        old_kinds, old_outputs = interfaces(Path(old_dir) / name)
        new_kinds, new_outputs = interfaces(Path(new_dir) / name)
        for kind in sorted(set(old_kinds) | set(new_kinds)):
            if kind not in old_kinds or kind not in new_kinds:
                rows.append((str(name), kind, ["interface only in " + ("new" if kind in new_kinds else "old")]))
                continue
            rows.append((str(name), kind, compare(run(Path(old_dir) / name, kind, old_outputs),
                                                  run(Path(new_dir) / name, kind, new_outputs))))
    return rows


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--run"]:
        run_here(argv[1], argv[2], argv[3], argv[4:])
        return 0
    if len(argv) != 2 or not all(Path(a).is_dir() for a in argv):
        print("error: give two folders of built FMUs: OLD_DIR NEW_DIR", file=sys.stderr)
        return 2
    rows = table(Path(argv[0]), Path(argv[1]))
    print("| FMU | interface | result |\n| --- | --- | --- |")
    for name, kind, notes in rows:
        print(f"| {name} | {kind} | {'; '.join(notes) if notes else 'identical'} |", flush=True)
    unexplained = any(note for _, _, notes in rows for note in notes
                      if not note.startswith(("new output", "only in new", "interface only in new")))
    return 1 if unexplained else 0


if __name__ == "__main__":
    sys.exit(main())
