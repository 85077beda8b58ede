"""`vibrofmu report`: the numbers in README.md and docs/*.md regenerated (report.py holds the blocks)."""
import contextlib
import sys
from pathlib import Path

from vibrofmu import paths
from vibrofmu.commands import bench, oafm, stability
from vibrofmu.commands.common import Command, Unused, built_all, invoke
from vibrofmu.report import NAMES, REPO_ROOT  # a light module: the standard library only at its top


def options(p):
    p.add_argument("--from", dest="sources", action="append", default=[], metavar="DIR",
                   help="folder with the summaries of the blocks made from studies (a bench.json, an oafm, "
                        "stability or continuation summary.json, a cusp_order.json, ...; repeatable; default: run "
                        "oafm, stability, bench, the documented cascade's continuation and the cusp study now)")
    p.add_argument("--quick", action="store_true", help="container comparison at H = 0.1, 0.05 only; oafm study to "
                                                        "order 3; bench --quick (default: off: the full runs)")
    p.add_argument("--check", action="store_true",
                   help="re-compute every block that does not depend on the machine (accuracy, ssp, ssp_orderings, "
                        "container, ranges, calibration_replay, and oafm, stability, cascade, cusp_order, curve_speed "
                        "and auto from the --from summaries or else fresh runs: their timings are not compared) and "
                        "compare with the documents; write nothing (default: off)")
    p.add_argument("--out", default=None, metavar="DIR",
                   help="write the documents with the regenerated blocks to DIR (README.md, docs/*.md) instead of "
                        f"rewriting them; --quick and --from always do (default: {QUICK_OUT} with --quick or --from, "
                        "else the documents under --root are rewritten)")
    p.add_argument("--only", nargs="+", choices=NAMES, default=None, help="regenerate these blocks only (default: all)")
    p.add_argument("--fmu-dir", default=None, help="where the FMUs are (default: build/; built when missing)")
    p.add_argument("--root", default=str(REPO_ROOT), help="the repository whose README.md and docs/ are "
                                                          "rewritten (default: this checkout)")


QUICK_OUT = "out/report"  # where --quick and --from write their documents: never the published ones
# the blocks --check does not compare, and why (printed by every --check); every other block of report.NAMES is
# compared (tests/docs/test_docs.py: each name is compared or listed here)
NOT_CHECKED = {"machine": "where and when the numbers were taken", "speed": "timings and instruction counts: they "
               "depend on the machine (CPU, compiler, libm) and its load", "peers": "timings of other ODE solvers "
               "beside ours: they depend on the machine and its load (`vibrofmu bench --peers --out DIR`, then "
               "`vibrofmu report --from DIR --only peers`)",
               "calibration": "the rungs' error estimates against their measured errors: an hour of campaigns "
               "(docs/rungs.md names them; then `vibrofmu report --from DIR --only calibration`); the first scenes "
               "of each are compared (calibration_replay)",
               "fuzz": "a fuzzing campaign's executions, rates and coverage: they depend on the machine, its load "
               "and the campaign's length (`python3 tests/fuzz/run.py --seconds S --out DIR`, then `vibrofmu report "
               "--from DIR --only fuzz`)",
               "auto_costs": "the cheap rungs' set-up, table and fit costs and the paper scene's candidates: times, "
               "they depend on the machine and its load (`python -m vibrofmu.analyses.error_calibration costs` and "
               "`pair`, then `vibrofmu report --from DIR --only auto_costs`)",
               "auto_setup": "fidelity auto's set-up and the estimates' share of the initialisation: times, they "
               "depend on the machine and its load (`vibrofmu bench --auto-only --out DIR`, then `vibrofmu report "
               "--from DIR --only auto_setup`)"}
# compared by --check too: from the --from summaries, else from fresh full runs of `vibrofmu oafm` and `stability`
# (about a minute of CPU on 2 cores), the documented cascade's `vibrofmu continuation` (measured 7 s CPU with its
# plots), the cusp study (5 s CPU), `vibrofmu bench --curve` (17 s CPU, mostly its check of every point by SciPy)
# and the replay of the documented auto campaign (error_calibration.auto_replay: 10 s CPU), their timings masked
# (report.comparable); the bench is not run: the speed block is not compared
FROM_CHECKED = ("oafm", "stability", "cascade", "cusp_order", "curve_speed", "auto")
STUDIES = ("oafm", "stability", "bench", "cascade", "cusp_order")  # what a full run runs (without --from)
# what --check runs besides (a full run leaves these blocks as they are: the curve's timings come from a `bench
# --curve` given with --from, and the replay derives only part of the auto block, its campaign takes an hour)
CHECK_STUDIES = ("curve_speed", "auto")


# The studies each generated block reads: a block is rewritten only when every one of them completed (the speed block
# gathers the three summaries; from two of them it would silently lose the bench's lines).
BLOCK_STUDIES = {"oafm": {"oafm"}, "stability": {"stability"}, "speed": {"oafm", "stability", "bench"},
                 "auto_setup": {"bench"}, "cascade": {"cascade"}, "cusp_order": {"cusp_order"},
                 "curve_speed": {"curve_speed"}, "auto": {"auto"}}
NEEDS_FMUS = ("accuracy", "ssp", "ssp_orderings", "container")  # the blocks that run the FMUs themselves
STUDIES_WITH_FMUS = ("oafm", "stability", "bench")  # the studies that run the plant FMU (not the continuations)


def run_studies(fmu_dir: Path, work_dir: Path, quick: bool, failed: set | None = None,
                which=STUDIES) -> list[Path]:
    """Run the studies `which` of STUDIES and CHECK_STUDIES (quick: fewer orders, quick bench; the cascade, the cusp
    study, the curve and the auto replay take seconds and run in full) into work_dir; the folders of those that
    completed (a failure is printed, added to `failed` and skipped)."""
    from vibrofmu.commands import continuation
    from vibrofmu.report import CASCADE_ARGV

    plant = str(fmu_dir / paths.PLANT_NAME)
    runs = {"oafm": (oafm.COMMAND, ["--fmu", plant] + (["--study-max-order", "3"] if quick else [])),
            "stability": (stability.COMMAND, ["--fmu", plant]),
            "bench": (bench.COMMAND, ["--fmu", plant] + (["--quick"] if quick else [])),
            "cascade": (continuation.COMMAND, list(CASCADE_ARGV)),
            "cusp_order": (cusp_study, []),
            "curve_speed": (bench.COMMAND, ["--curve"]),
            "auto": (auto_replay_study, [])}
    folders = []
    for name, (command, argv) in runs.items():
        if name not in which:
            continue
        folder = work_dir / name
        said = (IN_PROCESS[command] if command in IN_PROCESS else
                " ".join(["vibrofmu", command.name, *(argv[2:] if name in STUDIES_WITH_FMUS else argv)]))
        print(f"report: running {said} ...", file=sys.stderr, flush=True)
        try:
            code = command(folder) if command in IN_PROCESS else invoke(command, argv + ["--out", str(folder)])
        except Exception as error:  # a failing study must not lose the other blocks: say which and go on
            # (Ctrl-C is no Exception: it stops the report before any document is rewritten)
            code = f"{type(error).__name__}: {error}"
        if code != 0:
            blocks = sorted(block for block, studies in BLOCK_STUDIES.items() if name in studies)
            print(f"error: vibrofmu {name} failed ({code}); the blocks that read its summary ({', '.join(blocks)}) "
                  "are not updated", file=sys.stderr)
            if failed is not None:
                failed.add(name)
            continue
        folders.append(folder)
    return folders


def cusp_study(folder: Path) -> int:
    """`python3 -m vibrofmu.analyses.cusp_order folder` in this process (its exit code)."""
    from vibrofmu.analyses import cusp_order

    return cusp_order.main([str(folder)])


def auto_replay_study(folder: Path) -> int:
    """error_calibration.auto_replay of the documented auto campaign (DOCUMENTED_AUTO), in this process, into
    folder/report.AUTO_REPLAY (0)."""
    from vibrofmu.analyses.error_calibration import DOCUMENTED_AUTO, auto_replay
    from vibrofmu.output import export
    from vibrofmu.report import AUTO_REPLAY

    folder.mkdir(parents=True, exist_ok=True)
    export.write_json(folder / AUTO_REPLAY, auto_replay(*DOCUMENTED_AUTO))
    return 0


IN_PROCESS = {cusp_study: "python3 -m vibrofmu.analyses.cusp_order",  # the studies run as functions, and how the
              auto_replay_study: "the replay of the documented `python -m vibrofmu.analyses.error_calibration auto` "
                                 "campaign (auto's choices and their runs)"}  # report names them


def run(args) -> int:
    import tempfile

    # pythonfmu's builder imported before any FMU runs in this process: an FMU run first would make `pythonfmu`
    # the copy packed in its resources (no builder binaries), and the bench's own closed-loop build would fail
    # ("has no binaries/linux64/HertzEAClosedLoop.so")
    import vibrofmu.fmus.build  # noqa: F401
    from vibrofmu.report import (DETERMINISTIC, FROM_SUMMARIES, SOURCE_FILES, ReportError, comparable, documents,
                                 generate, parse_blocks, replace_blocks, start_record, summary_block)

    start = start_record()  # the machine block's time and load: before the studies load the machine
    root = Path(args.root)
    if not (root / "README.md").is_file() or not (root / "docs").is_dir():
        print(f"error: --root {root}: no README.md and docs/ there (run report in a checkout of vibrofmu, or give "
              "--root)", file=sys.stderr)
        return 2
    sources = [Path(s) for s in args.sources]
    for source in sources:
        if not source.is_dir():
            print(f"error: --from {source}: not a folder", file=sys.stderr)
            return 2
    try:
        texts = {doc: doc.read_text() for doc in documents(root) if doc.is_file()}
        found = {doc: parse_blocks(text, str(doc)) for doc, text in texts.items()}
    except ReportError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    out = None  # the folder the documents are written to, None: rewritten in place (a full run only)
    if not args.check and (args.out is not None or args.quick or sources):
        from vibrofmu.commands.common import UserError, writable_folder

        try:
            out = writable_folder(args.out or QUICK_OUT)
        except UserError as error:
            print(f"error: {error}", file=sys.stderr)
            return 2
        if any((out / doc.relative_to(root)).resolve() == doc.resolve() for doc in texts):
            print(f"error: --out {out}: that would rewrite the documents under {root} (give another folder)",
                  file=sys.stderr)
            return 2
    names = (DETERMINISTIC + FROM_CHECKED) if args.check else (args.only or NAMES)
    if sources and args.only:  # a block asked for by name whose summary is in no --from folder: say so now
        try:
            missing = [name for name in names if name in FROM_SUMMARIES and summary_block(name, sources) is None]
        except ReportError as error:  # a summary there but damaged
            print(f"error: --from {', '.join(args.sources)}: {error}", file=sys.stderr)
            return 2
        if missing:
            text = "; ".join(f"{name} needs {SOURCE_FILES[name]}" for name in missing)
            print(f"error: --from {', '.join(args.sources)}: no summary for the block{'s' * (len(missing) > 1)} "
                  f"asked for ({text})", file=sys.stderr)
            return 2
    # the studies to run: without --from those of the blocks asked for (a full run: all of STUDIES); with --check
    # and --from, those of the compared blocks whose summaries no --from folder holds
    wanted = set().union(*(BLOCK_STUDIES.get(name, set()) for name in names))
    if not args.check:
        wanted -= set(CHECK_STUDIES)
    if args.check and sources:
        wanted = {name for name in FROM_CHECKED if summary_block(name, sources) is None}
    elif sources:
        wanted = set()
    studies = tuple(study for study in STUDIES + CHECK_STUDIES if study in wanted)
    fmu_dir = Path(args.fmu_dir or paths.build_dir())
    if any(name in NEEDS_FMUS for name in names) or any(study in STUDIES_WITH_FMUS for study in studies):
        fmu_dir = built_all(fmu_dir)  # the blocks from summaries alone (--from) and the continuations run no FMU
    failed = set()  # the studies that did not complete
    with tempfile.TemporaryDirectory() as work_dir:
        if studies:
            sources = sources + run_studies(fmu_dir, Path(work_dir), args.quick, failed, studies)
            names = [name for name in names if not BLOCK_STUDIES.get(name, set()) & failed]
        try:
            bodies = generate(names, fmu_dir, sources, args.quick, Path(work_dir), start)
        except ReportError as error:  # a damaged summary in a --from folder (fuzz.json): nothing is written
            print(f"error: {error}", file=sys.stderr)
            return 2
    missing = [name for name in names if name not in bodies]  # never silent (a failed study said why above)
    if missing:
        where = ("--from " + ", ".join(args.sources)) if args.sources else "the studies' runs"
        text = "; ".join(f"{name} needs {SOURCE_FILES[name]}" for name in missing)
        print(f"{'error' if args.check else 'warning'}: {where}: blocks {', '.join(missing)} not regenerated "
              f"({text})", file=sys.stderr)
    if args.check:
        stale = [f"{doc.relative_to(root)}: {name}" for doc, blocks in found.items() for name, body in blocks.items()
                 if name in bodies and comparable(name, body) != comparable(name, bodies[name])]
        if stale:
            print("error: generated numbers differ from the documents (run `vibrofmu report`): " + "; ".join(stale),
                  file=sys.stderr)
            return 1
        checked = sorted({name for blocks in found.values() for name in blocks if name in bodies})
        print(f"report --check: blocks {', '.join(checked) or 'none'} match a fresh run")
        print("report --check: not compared: " + "; ".join(f"{name} ({why})" for name, why in NOT_CHECKED.items()))
        return 1 if failed or missing else 0  # a block left uncompared (its study failed): never a silent pass
    from vibrofmu.output.export import atomic

    # every document written to a temporary name first, then all renamed: a Ctrl-C leaves each document either
    # as it was or updated, never half-written (and none is touched before every block was generated)
    # the documents as they are now, not as they were when the run started: an edit made while the studies ran
    # (minutes) is kept, only the generated blocks change
    texts = {doc: doc.read_text() for doc in texts}
    if out is not None:  # --quick, --from or --out: every document, the blocks regenerated, into out
        targets = {doc: out / doc.relative_to(root) for doc in texts}
        with contextlib.ExitStack() as stack:
            for doc, text in texts.items():
                targets[doc].parent.mkdir(parents=True, exist_ok=True)
                stack.enter_context(atomic(targets[doc])).write_text(replace_blocks(text, bodies))
        for doc, target in targets.items():
            regenerated = [n for n in found[doc] if n in bodies]
            print(f"wrote {target}" + (f": {', '.join(regenerated)}" if regenerated else ""))
        print(f"report: the documents under {root} are unchanged (--quick and --from write to a folder: only a full "
              "run rewrites them)" if args.quick or sources else f"report: the documents under {root} are unchanged")
        return 1 if failed else 0
    changed = {doc: new for doc, text in texts.items() if (new := replace_blocks(text, bodies)) != text}
    with contextlib.ExitStack() as stack:
        for doc, new in changed.items():
            stack.enter_context(atomic(doc)).write_text(new)
    for doc in changed:
        print(f"updated {doc.relative_to(root)}: " + ", ".join(n for n in found[doc] if n in bodies))
    if not changed:
        print(f"report: blocks {', '.join(bodies) or 'none'} regenerated; the documents already hold them")
    return 1 if failed else 0  # the other blocks were written; a failed study still fails the report


def unused(args) -> list[Unused]:
    """--check compares the deterministic blocks, whichever --only names, and writes nothing."""
    return [Unused("only", "--check compares every deterministic block; leave --only out"),
            Unused("out", "--check writes nothing; leave --out out"),
            Unused("quick", "--check compares with the documents, which hold the full runs' numbers; leave --quick "
                            "out")] if args.check else []


COMMAND = Command("report", "regenerate the numbers in README.md and docs/*.md (blocks between "
                            "<!-- report:NAME --> markers)", options, run, unused)
