"""Build and run the libFuzzer targets of the FMI layers (tests/fuzz/*.c) under AddressSanitizer and
UndefinedBehaviorSanitizer.

    python3 tests/fuzz/run.py [--seconds 60] [--jobs 2] [--runs N] [--out build/fuzz] [TARGET ...]

Targets: calls_<Model> and state_<Model> for each native FMU (fuzz_native.c with FUZZ_CALLS / FUZZ_STATE, compiled
with the model's native sources for FMI 3.0 -- which hold the FMI 2.0 layer too -- and its generated headers,
vibrofmu.fmus.native.write_sources), and layer (fuzz_layer.c on fmu_src/fmi/fmi2_layer.c).  Each runs from its
seed corpus tests/fuzz/corpus/<target>/ (read only) plus a working corpus <out>/corpus/<target>/; --seconds is the
wall-clock budget of the whole run, shared by the targets (--jobs at a time); --runs N runs each target for N
executions instead.  Exit 1 on a finding (the input is kept as <out>/findings/<target>-crash-...; rerun it with
<out>/bin/<target> FILE), 2 when clang or a target cannot be built.  The compiler: $FUZZ_CC, else clang-14, else
clang (Debian: apt-get install clang-14 libclang-rt-14-dev libfuzzer-14-dev).
"""
from __future__ import annotations

import argparse
import concurrent.futures
import os
import re
import shutil
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
MODELS = ("HertzEAOscillator", "AdaptiveLyapunovController", "HertzEAClosedLoop")
SANITIZE = "-fsanitize=address,undefined"
# -fno-sanitize-recover: every UBSan report aborts (a finding), as ASan's do
FLAGS = ("-g", "-O1", "-Wall", "-Wextra", "-std=c11", "-ffp-contract=off", "-fno-sanitize-recover=all", "-fno-omit-frame-pointer")


def targets() -> list[str]:
    return [f"{kind}_{model}" for model in MODELS for kind in ("calls", "state")] + ["layer"]


def compiler() -> str:
    for name in (os.environ.get("FUZZ_CC"), "clang-14", "clang"):
        if name and shutil.which(name):
            return name
    sys.exit("error: no clang (set FUZZ_CC, or apt-get install clang-14 libclang-rt-14-dev libfuzzer-14-dev)")


def model_description(model: str) -> bytes:
    """The pythonfmu slave's modelDescription.xml (pythonfmu's own extraction; no FMU is built)."""
    from pythonfmu.builder import get_model_description

    from vibrofmu.fmus.entry import importable
    from vibrofmu.paths import FMU_SRC

    with importable(FMU_SRC):
        _, xml = get_model_description(FMU_SRC / f"{model}.py", model, model)
    return ET.tostring(xml, encoding="utf-8")


def run(cmd: list[str]) -> None:
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        print(f"error: {' '.join(cmd)}\n{proc.stderr}", file=sys.stderr)
        sys.exit(2)


def build(out: Path, wanted: list[str], skip_null: bool = False) -> None:
    """<out>/bin/<target> for each wanted target (rebuilt every time: the sources may have changed)."""
    from vibrofmu.fmus import native, toolchain
    from vibrofmu.paths import FMU_SRC

    cc = compiler()
    include = toolchain.fmi_include()
    (out / "bin").mkdir(parents=True, exist_ok=True)
    sanitize = "-fsanitize=" + SANITIZE.split("=")[1]
    compiles, links = [], []
    for model in MODELS:
        kinds = [k for k in ("calls", "state") if f"{k}_{model}" in wanted]
        if not kinds:
            continue
        sources = out / "src" / model
        if sources.exists():
            shutil.rmtree(sources)
        c_files = native.write_sources(model, model_description(model), sources, fmi_version=3)
        objects = []
        for name in c_files:  # the model's sources once (instrumented), linked into both of its targets
            objects.append(str(sources / f"{name}.o"))
            compiles.append([cc, *FLAGS, "-fsanitize=fuzzer-no-link", sanitize, f"-I{sources}", include, "-c",
                             "-o", objects[-1], str(sources / name)])
        for kind in kinds:
            define = [f"-DFUZZ_{kind.upper()}", *(["-DFUZZ_SKIP_NULL"] if skip_null else [])]
            links.append([cc, *FLAGS, "-fsanitize=fuzzer", sanitize, *define, f"-I{sources}", f"-I{HERE}", include,
                          "-o", str(out / "bin" / f"{kind}_{model}"), str(HERE / "fuzz_native.c"), *objects, "-lm"])
    if "layer" in wanted:
        links.append([cc, *FLAGS, "-fsanitize=fuzzer", sanitize, f"-I{FMU_SRC / 'fmi'}", f"-I{HERE}", include, "-o",
                      str(out / "bin" / "layer"), str(HERE / "fuzz_layer.c"), str(FMU_SRC / "fmi" / "fmi2_layer.c"),
                      "-lm"])
    with concurrent.futures.ThreadPoolExecutor(max_workers=os.cpu_count() or 2) as pool:
        list(pool.map(run, compiles))
        list(pool.map(run, links))


STAT = re.compile(r"^stat::(\w+):\s*(\d+)", re.M)
DONE = re.compile(r"#(\d+)\s+(?:DONE|pulse|NEW|REDUCE|INITED)\s+cov: (\d+) ft: (\d+) corp: (\d+)")


def fuzz(out: Path, target: str, seconds: float | None, runs: int | None) -> dict:
    corpus = out / "corpus" / target
    corpus.mkdir(parents=True, exist_ok=True)
    findings = out / "findings"
    findings.mkdir(parents=True, exist_ok=True)
    seeds = HERE / "corpus" / target
    limit = [f"-runs={runs}"] if runs is not None else [f"-max_total_time={max(1, int(seconds))}"]
    # -timeout: one input may take at most 10 s (a hang is a finding); -rss_limit_mb: a leak or a blow-up is one;
    # -max_len: the longest program the targets read in full
    cmd = [str(out / "bin" / target), *limit, "-timeout=10", "-rss_limit_mb=2048", "-max_len=512",
           "-print_final_stats=1", f"-artifact_prefix={findings}/{target}-", str(corpus),
           *([str(seeds)] if seeds.is_dir() else [])]
    start = time.monotonic()
    proc = subprocess.run(cmd, capture_output=True, text=True, env={**os.environ, "ASAN_OPTIONS": "detect_leaks=1",
                                                                    "UBSAN_OPTIONS": "print_stacktrace=1"})
    elapsed = time.monotonic() - start
    stats = {k: int(v) for k, v in STAT.findall(proc.stderr)}
    cov = DONE.findall(proc.stderr)
    result = {"target": target, "seconds": elapsed, "returncode": proc.returncode,
              "runs": stats.get("number_of_executed_units", 0), "exec_per_sec": stats.get("average_exec_per_sec", 0),
              "cov": int(cov[-1][1]) if cov else 0, "ft": int(cov[-1][2]) if cov else 0,
              "corpus": int(cov[-1][3]) if cov else 0, "log": proc.stderr}
    return result


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("targets", nargs="*", help=f"default: all ({', '.join(targets())})")
    parser.add_argument("--seconds", type=float, default=60.0, help="wall-clock budget of the whole run")
    parser.add_argument("--runs", type=int, default=None, help="executions per target (instead of --seconds)")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--out", type=Path, default=ROOT / "build" / "fuzz")
    parser.add_argument("--no-build", action="store_true", help="reuse <out>/bin")
    parser.add_argument("--skip-null", action="store_true",
                        help="no NULL pointer arguments (to look past a known NULL-argument finding)")
    args = parser.parse_args(argv)
    wanted = args.targets or targets()
    unknown = sorted(set(wanted) - set(targets()))
    if unknown:
        print(f"error: unknown target(s) {', '.join(unknown)}; known: {', '.join(targets())}", file=sys.stderr)
        return 2
    out = args.out.resolve()
    start = time.monotonic()
    if not args.no_build:
        build(out, wanted, args.skip_null)
    built = time.monotonic() - start
    # each target's share of the wall-clock budget, --jobs at a time
    share = args.seconds * args.jobs / len(wanted)
    with concurrent.futures.ThreadPoolExecutor(max_workers=args.jobs) as pool:
        results = list(pool.map(lambda t: fuzz(out, t, share, args.runs), wanted))
    failed = 0
    print(f"fuzz: built in {built:.0f} s; {len(wanted)} targets, {args.jobs} at a time")
    print(f"{'target':40s} {'executions':>12s} {'exec/s':>8s} {'cov':>6s} {'ft':>6s} {'corpus':>7s} {'s':>6s}")
    for r in results:
        print(f"{r['target']:40s} {r['runs']:12d} {r['exec_per_sec']:8d} {r['cov']:6d} {r['ft']:6d} "
              f"{r['corpus']:7d} {r['seconds']:6.0f}{'  FINDING' if r['returncode'] else ''}")
        if r["returncode"] != 0:
            failed += 1
            tail = r["log"].splitlines()
            start_at = next((i for i, line in enumerate(tail) if "ERROR" in line or "FUZZ FINDING" in line
                             or "runtime error" in line), max(0, len(tail) - 40))
            print("\n".join(tail[start_at:start_at + 60]), file=sys.stderr)
    print(f"fuzz: {failed} finding(s) in {time.monotonic() - start:.0f} s")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
