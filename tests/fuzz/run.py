"""Build and run the libFuzzer targets of the FMI layers (tests/fuzz/*.c) under AddressSanitizer and
UndefinedBehaviorSanitizer.

    python3 tests/fuzz/run.py [--seconds 60] [--jobs 2] [--runs N] [--timeout 30] [--out build/fuzz] [TARGET ...]
    python3 tests/fuzz/run.py --merge tests/fuzz/merged [--out build/fuzz] [TARGET ...]

Each run writes <out>/fuzz.json (the command, the machine's CPUs and load, the sources' commit, and per target its
executions, CPU seconds, coverage, corpus and finding): `vibrofmu report --from <out> --only fuzz` makes
docs/robustness.md's campaign block of it.

Targets: calls_<Model> and state_<Model> for each native FMU (fuzz_native.c with FUZZ_CALLS / FUZZ_STATE, compiled
with the model's native sources for FMI 3.0 -- which hold the FMI 2.0 layer too -- and its generated headers,
vibrofmu.fmus.native.write_sources), and layer (fuzz_layer.c on fmu_src/fmi/fmi2_layer.c).  Each runs from its
seeds -- tests/fuzz/corpus/<target>/ (seeds.py's programs) and tests/fuzz/merged/<target>.hex (a campaign's
corpus, minimized: --merge) -- read only, plus a working corpus <out>/corpus/<target>/; --seconds is the wall-clock budget
of the whole run, shared by the targets (--jobs at a time); --runs N stops each target after N executions (with
--seconds too, at whichever limit comes first).  Exit 1 on a finding (the input is kept as
<out>/findings/<target>-crash-...; rerun it with <out>/bin/<target> FILE), 2 when clang or a target cannot be
built, 130 (143) when stopped by SIGINT (SIGTERM): the targets running are asked to stop as libFuzzer stops
gracefully (SIGUSR1: the input at hand finished, its final statistics printed), those not started are not run, and
the summary holds what ran.  The compiler: $FUZZ_CC, else clang-14, else clang (Debian: apt-get install clang-14 libclang-rt-14-dev
libfuzzer-14-dev).
"""
from __future__ import annotations

import argparse
import concurrent.futures
import hashlib
import json
import os
import re
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
import xml.etree.ElementTree as ET
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
MODELS = ("HertzEAOscillator", "AdaptiveLyapunovController", "HertzEAClosedLoop")
SANITIZE = "-fsanitize=address,undefined"
# -fno-sanitize-recover: every UBSan report aborts (a finding), as ASan's do.
# -fsanitize-coverage-ignorelist: the functions whose coverage tells the fuzzer nothing but costs a callback per
# byte (coverage_ignore.txt: the states' checksum loops); ASan and UBSan still check them.
# -DVK_NO_UNROLL: the core's DOP853 keeps its stage loops rolled (fmu_src/core/dop853.c's UNROLL: unrolled, the file
# alone took clang 37 s under the sanitizers, the whole fuzz build 124 s; rolled 2 s and 25 s).
FLAGS = ("-g", "-O1", "-DVK_NO_UNROLL", "-Wall", "-Wextra", "-std=c11", "-ffp-contract=off", "-fno-sanitize-recover=all",
         "-fno-omit-frame-pointer", f"-fsanitize-coverage-ignorelist={HERE / 'coverage_ignore.txt'}")
# The most solver steps one doStep may take in the fuzz build (the FMUs allow 10^6: rules.h's
# RULE_MAX_STEPS_PER_DOSTEP, closedloop.h's VL_MAX_STEPS_PER_DOSTEP).  Under the sanitizers a closed-loop DOP853
# step costs about 44 us of CPU (2 us in the FMU's -O2 build), so an input that set max_step or rtol small ran one
# doStep for 44 s of CPU, minutes of wall-clock time on a loaded machine: the budget's work, not a hang.  10^3 steps
# keep a doStep of the fuzz build under 0.05 s of CPU and an input of 48 calls under about 2 s, and still take a
# doStep of the longest length the targets make (4 time units) at the default steps (RK4 0.01: 400 steps); the code
# paths are the FMU's, only the threshold moves: refused up front when h / max_step exceeds it, stopped with the
# budget's error when the adaptive solver spends it.
FUZZ_STEP_BUDGET = 1000
BUDGET_MACROS = {"rules.h": "RULE_MAX_STEPS_PER_DOSTEP", "closedloop.h": "VL_MAX_STEPS_PER_DOSTEP"}


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


def fuzz_step_budget(sources: Path) -> None:
    """The generated sources with FUZZ_STEP_BUDGET solver steps per doStep (every copy of the 10^6 present)."""
    for name, macro in BUDGET_MACROS.items():
        header = sources / name
        if not header.exists():
            continue
        text, n = re.subn(rf"^#define {macro} \S+$", f"#define {macro} {FUZZ_STEP_BUDGET:.1f}", header.read_text(),
                          flags=re.M)
        if n != 1:
            sys.exit(f"error: {header} has no '#define {macro}' line to set the fuzz build's step budget in")
        header.write_text(text)
    if not (sources / "rules.h").exists():
        sys.exit(f"error: no rules.h in {sources}")


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
        fuzz_step_budget(sources)
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


# ASan's quarantine (freed memory held back to catch a use after free) at 64 MB rather than 256 MB, and never
# handed back to the system: an input allocates well under 1 MB (a closed-loop instance and its states, 20 KB
# each), so 64 MB still spans hundreds of inputs, while each target's resident set stays near 150 MB instead of
# 400 MB (the machine is shared) and the page faults of re-touching released memory (8 % of a state target's
# time) are gone.  Leaks are findings (libFuzzer checks an input whose mallocs and frees do not match).
ASAN_OPTIONS = "detect_leaks=1:quarantine_size_mb=64:allocator_release_to_os_interval_ms=-1"


class Stop:
    """A run stopped early (SIGINT, SIGTERM: Ctrl-C, a scheduler's end of a slot): each target running is sent
    SIGUSR1, on which libFuzzer finishes the input at hand, prints its final statistics and exits 0, so its
    executions are kept; a target not yet started is not run.  (A terminal's Ctrl-C reaches the targets too, in the
    same process group: libFuzzer then exits with its "interrupted" code, 72, after the same statistics; that exit
    is not a finding once the run is stopping.)  Without it a stopped campaign lost every target's numbers: the
    summary is written when the last target ends."""

    INTERRUPTED = 72  # libFuzzer's -interrupted_exitcode default

    def __init__(self):
        self.signal: int | None = None
        self.lock = threading.Lock()
        self.running: set[subprocess.Popen] = set()

    def request(self, signum, _frame=None) -> None:
        self.signal = signum
        with self.lock:  # held only by the worker threads, briefly: the handler (main thread) never deadlocks on it
            for proc in self.running:
                proc.send_signal(signal.SIGUSR1)

    def started(self, proc: subprocess.Popen) -> None:
        with self.lock:
            self.running.add(proc)
            if self.signal is not None:  # stopped between the check before starting and now
                proc.send_signal(signal.SIGUSR1)

    def ended(self, proc: subprocess.Popen) -> None:
        with self.lock:
            self.running.discard(proc)


def fuzz(out: Path, target: str, seconds: float | None, runs: int | None, timeout: int = 30,
         stop: Stop | None = None) -> dict | None:
    corpus = out / "corpus" / target
    corpus.mkdir(parents=True, exist_ok=True)
    findings = out / "findings"
    findings.mkdir(parents=True, exist_ok=True)
    seeds = [d for d in (HERE / "corpus" / target, unpack_merged(out, target)) if d is not None and d.is_dir()]
    limit = [*([f"-runs={runs}"] if runs is not None else []),
             *([f"-max_total_time={max(1, int(seconds))}"] if seconds is not None else [])]
    # -timeout: the wall-clock seconds one input may take (a hang is a finding).  With FUZZ_STEP_BUDGET an input's
    # work is bounded: at most 48 calls (fuzz_native.c's MAX_OPS), each doStep at most 10^3 solver steps, so an
    # input needs at most about 2 s of CPU (44 closed-loop doSteps of 10^3 DOP853 steps: 1.9 s), most a few ms; 30 s
    # leaves room for a loaded machine (a campaign at nice 19 beside other work may need more: --timeout).
    # -rss_limit_mb: a leak or a blow-up is a finding; -max_len: the longest program the targets read in full.
    cmd = [str(out / "bin" / target), *limit, f"-timeout={timeout}", "-rss_limit_mb=2048", "-max_len=512",
           "-print_final_stats=1", f"-artifact_prefix={findings}/{target}-", str(corpus),
           *map(str, seeds)]
    if stop is not None and stop.signal is not None:
        return None  # the run was stopped before this target started
    start = time.monotonic()
    # the target's own CPU time (user + system, from wait4's resource usage): with --jobs > 1 or on a shared machine
    # the wall-clock seconds tell little about the work done
    with tempfile.TemporaryFile("w+") as log:
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=log, text=True,
                                env={**os.environ, "ASAN_OPTIONS": ASAN_OPTIONS, "UBSAN_OPTIONS": "print_stacktrace=1"})
        if stop is not None:
            stop.started(proc)
        _, status, usage = os.wait4(proc.pid, 0)
        if stop is not None:
            stop.ended(proc)
        proc.returncode = os.waitstatus_to_exitcode(status)  # reaped here: Popen must not wait for it again
        log.seek(0)
        stderr = log.read()
    elapsed = time.monotonic() - start
    stats = {k: int(v) for k, v in STAT.findall(stderr)}
    cov = DONE.findall(stderr)
    stopped = stop is not None and stop.signal is not None
    returncode = proc.returncode
    if stopped and returncode == Stop.INTERRUPTED and "libFuzzer: run interrupted" in stderr:
        returncode = 0  # the terminal's SIGINT, not a finding
    result = {"target": target, "seconds": elapsed, "cpu_seconds": usage.ru_utime + usage.ru_stime,
              "returncode": returncode, "stopped": stopped,
              "runs": stats.get("number_of_executed_units", 0), "exec_per_sec": stats.get("average_exec_per_sec", 0),
              "cov": int(cov[-1][1]) if cov else 0, "ft": int(cov[-1][2]) if cov else 0,
              "corpus": int(cov[-1][3]) if cov else 0, "log": stderr}
    return result


SUMMARY = "fuzz.json"  # <out>/fuzz.json: a run's summary (vibrofmu report --from <out> --only fuzz reads it)


def sources_commit() -> str | None:
    """The checkout's commit the targets were built from (with '+changes' when its tracked files differ), or None
    outside a git checkout."""
    try:
        head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short=12", "HEAD"], capture_output=True,
                              text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(ROOT), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None
    return head + ("+changes" if dirty else "")


def write_summary(out: Path, argv: list[str], args, started: tuple[float, tuple[float, float, float], str | None],
                  built: float, elapsed: float, results: list[dict], stopped: int | None = None) -> Path:
    """<out>/fuzz.json: the run (its command; started: when, the machine's load then and the sources' commit,
    taken before the build; the CPUs, the limits; the signal that stopped it early, if one did) and per target its
    executions, rates, CPU time, coverage, corpus, whether it found something and whether the stop cut it short."""
    summary = {"fuzz": {
        "command": shlex.join(["python3", "tests/fuzz/run.py", *argv]),
        "started_utc": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime(started[0])),
        "cpu_count": os.cpu_count(), "load_average_at_start": list(started[1]),
        "load_average_at_end": list(os.getloadavg()), "sources": started[2],
        "seconds": args.seconds, "runs_limit": args.runs, "jobs": args.jobs, "timeout": args.timeout,
        "skip_null": args.skip_null, "build_seconds": built, "elapsed_seconds": elapsed,
        "stopped": signal.Signals(stopped).name if stopped else None,
        "targets": [{"target": r["target"], "executions": r["runs"], "seconds": r["seconds"],
                     "cpu_seconds": r["cpu_seconds"], "exec_per_sec": r["exec_per_sec"], "cov": r["cov"],
                     "ft": r["ft"], "corpus": r["corpus"], "finding": r["returncode"] != 0,
                     "stopped": r.get("stopped", False)} for r in results]}}
    path = out / SUMMARY
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(summary, indent=1) + "\n")
    tmp.replace(path)
    return path


def unpack_merged(out: Path, target: str) -> Path | None:
    """<out>/merged/<target>/: the inputs of tests/fuzz/merged/<target>.hex (one input a line, in hex), one file
    each, for libFuzzer to read; None when there is no such file."""
    packed = HERE / "merged" / f"{target}.hex"
    if not packed.exists():
        return None
    folder = out / "merged" / target
    if folder.exists():
        shutil.rmtree(folder)
    folder.mkdir(parents=True)
    for line in packed.read_text().split():
        data = bytes.fromhex(line)
        (folder / hashlib.sha1(data).hexdigest()).write_bytes(data)
    return folder


def merge(out: Path, target: str, dest: Path) -> int:
    """dest/<target>.hex: a smallest-first subset of the working corpus <out>/corpus/<target>/ and of the committed
    tests/fuzz/merged/<target>.hex that covers every edge they cover beyond the seeds (libFuzzer's -merge=1 on edges
    alone, -use_counters=0: with hit counts it keeps about twice as many), one input a line in hex (a text file rather
    than hundreds of binary ones).  The committed tests/fuzz/merged/ is this, so that a short run starts from the
    coverage the campaigns reached; the committed inputs take part because a run reads them but writes only what it
    adds to the working corpus (without them a merge kept only what the last run's working corpus covers).  The
    number of inputs kept."""
    seeds = HERE / "corpus" / target
    work = out / "merge" / target
    if work.exists():
        shutil.rmtree(work)
    work.mkdir(parents=True)
    for seed in seeds.iterdir():  # the seeds first: only what they miss is added
        shutil.copy(seed, work / seed.name)
    committed = unpack_merged(out, target)
    proc = subprocess.run([str(out / "bin" / target), "-merge=1", "-use_counters=0", "-timeout=60", str(work),
                           *([str(committed)] if committed is not None else []), str(out / "corpus" / target)],
                          capture_output=True, text=True, env={**os.environ, "ASAN_OPTIONS": ASAN_OPTIONS})
    if proc.returncode != 0:
        print(f"error: merging {target}\n{proc.stderr[-3000:]}", file=sys.stderr)
        sys.exit(1)
    known = {seed.read_bytes() for seed in seeds.iterdir()}
    kept = sorted(f.read_bytes().hex() for f in work.iterdir() if f.read_bytes() not in known)
    dest.mkdir(parents=True, exist_ok=True)
    (dest / f"{target}.hex").write_text("".join(line + "\n" for line in kept))
    return len(kept)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("targets", nargs="*", help=f"default: all ({', '.join(targets())})")
    parser.add_argument("--seconds", type=float, default=None, help="wall-clock budget of the whole run (default "
                        "60 s without --runs)")
    parser.add_argument("--runs", type=int, default=None,
                        help="executions per target (with --seconds: whichever limit comes first)")
    parser.add_argument("--timeout", type=int, default=30, help="wall-clock seconds one input may take (a finding)")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--out", type=Path, default=ROOT / "build" / "fuzz")
    parser.add_argument("--no-build", action="store_true", help="reuse <out>/bin")
    parser.add_argument("--skip-null", action="store_true",
                        help="no NULL pointer arguments (to look past a known NULL-argument finding)")
    parser.add_argument("--merge", type=Path, metavar="DIR",
                        help="no fuzzing: write DIR/<target>.hex, the working corpus minimized (tests/fuzz/merged)")
    argv = sys.argv[1:] if argv is None else argv
    args = parser.parse_args(argv)
    wanted = args.targets or targets()
    unknown = sorted(set(wanted) - set(targets()))
    if unknown:
        print(f"error: unknown target(s) {', '.join(unknown)}; known: {', '.join(targets())}", file=sys.stderr)
        return 2
    out = args.out.resolve()
    # when, the machine's load before the build loads it, and the sources built (a commit made during a long run
    # is not the campaign's)
    started = time.time(), os.getloadavg(), sources_commit()
    start = time.monotonic()
    if args.merge is not None:
        for target in wanted:
            print(f"{target}: {merge(out, target, args.merge.resolve())} inputs kept")
        return 0
    if not args.no_build:
        build(out, wanted, args.skip_null)
    built = time.monotonic() - start
    # each target's share of the wall-clock budget, --jobs at a time
    seconds = 60.0 if args.seconds is None and args.runs is None else args.seconds
    share = None if seconds is None else seconds * args.jobs / len(wanted)
    stop = Stop()
    handlers = {signum: signal.signal(signum, stop.request) for signum in (signal.SIGINT, signal.SIGTERM)}
    try:
        with concurrent.futures.ThreadPoolExecutor(max_workers=args.jobs) as pool:
            results = [r for r in pool.map(lambda t: fuzz(out, t, share, args.runs, args.timeout, stop), wanted)
                       if r is not None]
    finally:
        for signum, handler in handlers.items():
            signal.signal(signum, handler)
    failed = 0
    print(f"fuzz: built in {built:.0f} s; {len(wanted)} targets, {args.jobs} at a time")
    print(f"{'target':34s} {'executions':>11s} {'exec/s':>7s} {'CPU s':>7s} {'per CPU s':>9s} {'cov':>5s} {'ft':>6s} "
          f"{'corpus':>6s} {'s':>6s}")
    for r in results:
        per_cpu = r["runs"] / r["cpu_seconds"] if r["cpu_seconds"] > 0 else 0.0
        print(f"{r['target']:34s} {r['runs']:11d} {r['exec_per_sec']:7d} {r['cpu_seconds']:7.0f} {per_cpu:9.0f} "
              f"{r['cov']:5d} {r['ft']:6d} {r['corpus']:6d} {r['seconds']:6.0f}{'  FINDING' if r['returncode'] else ''}"
              f"{'  stopped' if r['stopped'] else ''}")
        if r["returncode"] != 0:
            failed += 1
            tail = r["log"].splitlines()
            start_at = next((i for i, line in enumerate(tail) if "ERROR" in line or "FUZZ FINDING" in line
                             or "runtime error" in line), max(0, len(tail) - 40))
            print("\n".join(tail[start_at:start_at + 60]), file=sys.stderr)
    elapsed = time.monotonic() - start
    summary = write_summary(out, argv, args, started, built, elapsed, results, stop.signal)
    print(f"fuzz: {failed} finding(s) in {elapsed:.0f} s; summary in {summary} (vibrofmu report --from {out} --only "
          "fuzz)" + (f"; stopped by {signal.Signals(stop.signal).name}: {len(results)} of {len(wanted)} targets ran"
                     if stop.signal is not None else ""))
    return 1 if failed else 128 + stop.signal if stop.signal is not None else 0


if __name__ == "__main__":
    sys.exit(main())
