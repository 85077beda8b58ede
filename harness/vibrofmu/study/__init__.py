"""`vibrofmu study KIND --out DIR`: response maps, basins of attraction and Monte Carlo on Dask distributed,
results in Parquet, compared with the averaged (slow-flow) predictions. See docs/studies.md.

Modules: spec (what to compute), cases (the cases and how one runs), engines (FMU under FMPy or the compiled
core), scheduling (cluster, batches, progress), storage (Parquet, resume), analysis (predictions, agreement,
summary), plots. Heavy modules (dask, pyarrow) are imported inside the command.
"""
from __future__ import annotations

import contextlib
import os
import signal
import sys
import time
from pathlib import Path



def cusp_test(client, spec, store, fmu_digest, out: Path) -> list[dict]:
    """The two-start bistability test (study.cusp) at every grid point where the sweeps ended apart, one Dask
    task per point; the results also go to DIR/cusp_test.json."""
    import numpy as np
    from distributed import as_completed

    from vibrofmu.output import export
    from vibrofmu.study.cusp import run_test_point, test_points
    from vibrofmu.study.scheduling import STOP, Progress

    table = store.load()
    data = {name: np.asarray(table.column(name).to_pylist()) for name in table.column_names}
    points = test_points(spec, data)
    progress = Progress(len(points), 0, "cusp test")
    futures = client.map(run_test_point, [spec.as_dict()] * len(points), [fmu_digest] * len(points), points,
                         pure=False)
    tests = []
    try:
        for future in as_completed(futures):
            if STOP.is_set():
                client.cancel(futures)
                raise KeyboardInterrupt
            tests.append(future.result())
            progress.update(1)
    finally:
        progress.close()
    tests.sort(key=lambda t: (t["Delta_index"], t["omega_index"]))
    export.write_json(out / "cusp_test.json", tests)
    return tests


def _end_workers(cluster) -> None:
    """End the local cluster's worker processes (ours) at once, and keep their nannies from restarting them: they
    ignore SIGINT, and a graceful close waits for the batch in hand (that took minutes)."""
    for nanny in list(getattr(cluster, "workers", {}).values()):
        nanny.auto_restart = False
        pid = getattr(nanny, "pid", None)
        if pid:
            with contextlib.suppress(OSError):
                os.kill(pid, signal.SIGKILL)


def end_children() -> None:
    """End every process this one started with multiprocessing (the local cluster's workers, also one still being
    spawned, which no nanny knows the pid of yet) before os._exit: a spawned child whose parent is gone while it reads
    its start-up data prints a multiprocessing traceback (EOFError) on the terminal after our last line."""
    import multiprocessing

    from vibrofmu.study.scheduling import SPAWNED

    pids = {child.pid for child in multiprocessing.active_children() if child.pid}
    pids |= {pid for pid in SPAWNED if _parent_of(pid) == os.getpid()}  # also one being spawned (still ours)
    for pid in pids:
        with contextlib.suppress(OSError):
            os.kill(pid, signal.SIGKILL)


def _parent_of(pid: int) -> int | None:
    """The parent's pid of process `pid` (Linux /proc), None when it is gone."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    return int(stat.rsplit(")", 1)[1].split()[1])


PLOTS = ("monte_carlo.png", "basins.png", "response_map.png")  # plots.plot's files, one per kind


def _remove_stale(out: Path) -> None:
    """Remove the plots and cusp test an earlier run left in DIR: they described that run's results; this run
    writes its own when it completes (an interrupted or failed run leaves none, rather than an old one)."""
    for name in (*PLOTS, "cusp_test.json"):
        (out / name).unlink(missing_ok=True)


def _end_resource_tracker() -> None:
    """End multiprocessing's resource tracker (our child process) before os._exit: the workers' semaphores it
    would report are gone with the process anyway (Linux unlinks them at creation)."""
    from multiprocessing import resource_tracker

    pid = getattr(resource_tracker._resource_tracker, "_pid", None)
    if pid:
        with contextlib.suppress(OSError):
            os.kill(pid, signal.SIGKILL)


def run(args) -> int:
    """`vibrofmu study` with its parsed options (commands/study.py)."""
    import hashlib

    from vibrofmu.output import export
    from vibrofmu import paths
    from vibrofmu.fmus.build import build_plant
    from vibrofmu.study import analysis, plots
    from vibrofmu.study.cases import make_cases
    from vibrofmu.study.scheduling import CLOSE_TIMEOUT_S, FmuFile, Progress, connect, execute, stop_on_sigint
    from vibrofmu.study.spec import SpecError, build_spec
    from vibrofmu.study.storage import Store

    spec = build_spec(args.kind, args.spec, args.set, args.quick, args.engine)
    if args.workers is not None and args.workers < 1:
        raise SpecError(f"--workers {args.workers}: must be >= 1")
    cases = make_cases(spec)
    if not cases:
        raise SpecError("empty study: no cases")
    if args.fmu is not None and spec.engine != "fmu":
        raise SpecError(f"--fmu {args.fmu}: the study's engine is {spec.engine!r} (the compiled kernel, no FMU); "
                        "leave --fmu out")
    out = Path(args.out)
    store = Store(out)
    new_folder = not out.exists()
    store.prepare({"digest": spec.digest(), "spec": spec.as_dict(), "cases": len(cases)}, args.resume)
    resumed = len(store.written)
    _remove_stale(out)

    fmu_digest = plugin = None
    if spec.engine == "fmu":
        fmu = Path(args.fmu) if args.fmu else paths.build_dir() / paths.PLANT_NAME  # (the command checked --fmu)
        if not fmu.exists():
            if args.fmu:
                raise SpecError(f"--fmu {fmu}: no such file")
            print(f"building {fmu} ...", file=sys.stderr)
            build_plant(fmu.parent)
        data = fmu.read_bytes()
        fmu_digest = hashlib.sha256(data).hexdigest()
        plugin = FmuFile(fmu_digest, data)

    started = time.perf_counter()
    try:
        client, cluster = connect(args.scheduler, args.workers)
    except SpecError:  # no scheduler there: nothing of the study is left behind (a new folder goes again)
        if new_folder:
            store.discard()
        raise
    except KeyboardInterrupt:
        print("interrupted while starting the cluster: nothing computed", file=sys.stderr)
        if not args.scheduler:  # a local cluster half started: its workers end with this process (see the end)
            sys.stdout.flush()
            sys.stderr.flush()
            end_children()
            _end_resource_tracker()
            os._exit(130)
        return 130
    interrupted, run, tests = False, {}, None
    workers = progress = None
    try:
        try:
            workers = len(client.scheduler_info(n_workers=-1)["workers"])
        except Exception:  # noqa: BLE001 - only for the summary
            pass
        progress = Progress(len(cases), resumed, args.kind)
        if plugin is not None:
            client.register_plugin(plugin)
        with stop_on_sigint():
            run = execute(client, spec, cases, store, fmu_digest, progress)
            if spec.kind == "response-map" and spec.settings.get("cusp_test"):
                progress.close()
                tests = cusp_test(client, spec, store, fmu_digest, out)
    except KeyboardInterrupt:
        interrupted = True
        if cluster is not None:
            _end_workers(cluster)
    finally:
        if progress is not None:
            progress.close()
        try:
            if not (interrupted and cluster is not None):  # (its workers ended: see the end)
                client.close(timeout=CLOSE_TIMEOUT_S)
                if cluster is not None:
                    cluster.close(timeout=CLOSE_TIMEOUT_S)
        except Exception:  # a cluster torn down by Ctrl-C: nothing left to close
            pass
        table = store.compact()
    wall = time.perf_counter() - started
    rows = 0 if table is None else table.num_rows
    done = len(store.load_cases())
    summary = {"kind": spec.kind, "engine": spec.engine, "cases": done, "cases_in_study": len(cases),
               "rows": rows, "computed_this_run": done - resumed, "resumed_from_disk": resumed,
               "workers": run.get("workers", workers), "wall_s": wall, "interrupted": interrupted,
               "scheduler": args.scheduler or "LocalCluster", "spec": spec.as_dict(), "run": run}
    if run:
        summary["projection_64_workers"] = analysis.projection(run, 64)
    written = [out / "spec.json"] + ([out / "results.parquet"] if (out / "results.parquet").exists() else [])
    if tests is not None:
        written.append(out / "cusp_test.json")
    if not interrupted and table is not None:
        result = analysis.analyse(spec, table, tests)
        summary.update(result["summary"])
        written += plots.plot(spec, table, result, out)
    export.write_json(out / "summary.json", summary)
    written.append(out / "summary.json")
    print(analysis.headline(summary), file=sys.stderr)
    print(f"wrote {out}/" + ", ".join(path.name for path in written))
    if interrupted:
        where = out / "results.parquet" if (out / "results.parquet").exists() else out
        print(f"interrupted: {done}/{len(cases)} cases in {where}; continue with --resume", file=sys.stderr)
        if cluster is not None:
            # everything is on disk (each file written whole and renamed); the local cluster's scheduler and nannies
            # live in this process and its workers are ended: closing them gracefully took 5-15 s more (timeouts,
            # then Dask's exit handlers), so the process ends here, within the few seconds a Ctrl-C may take
            sys.stdout.flush()
            sys.stderr.flush()
            end_children()  # (a worker still being spawned would print a traceback)
            _end_resource_tracker()  # (else it lists the workers' semaphores as "leaked", a dozen lines)
            os._exit(130)
        return 130
    if run.get("failed_batches") or done < len(cases):
        print(f"error: {len(cases) - done} cases not computed ({(run.get('failed_batches') or ['?'])[0]}); "
              f"continue with --resume", file=sys.stderr)
        return 1
    return 0
