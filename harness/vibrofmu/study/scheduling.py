"""Running the cases on Dask distributed: the cluster, the batch size, the progress bar, the results as
they arrive.

- Cluster: a LocalCluster of worker processes on 127.0.0.1 (one thread each, one per core by default), or
  an existing scheduler (--scheduler tcp://HOST:PORT; an unreachable one fails within CONNECT_TIMEOUT_S).
- The FMU reaches the workers through a worker plugin (FmuFile) holding its bytes: the scheduler installs it
  on every worker, also on a worker that joins or is restarted after a crash, and no shared file system is
  needed.
- Warm-up: every worker imports the study's modules and makes its engine first (warm_up, via client.run),
  outside the timed part: a fixed cost per worker that would dilute the measured speed-up.
- Batches: the scheduler's cost per task c_s is measured first (OVERHEAD_PROBE_TASKS empty tasks); one
  case per worker then runs (the pilot: it measures the cost per case c_w); when the
  first pilot case is back the rest go out in batches, largest first (guided_batches), none smaller than b,
  the smallest b with c_s / (b c_w) <= 5 % and b / c_s >= W / c_w (the scheduler keeps W workers busy), but
  small enough that every worker gets at least BATCHES_PER_WORKER batches (balance at the end).
- Worker loss: Dask re-runs the tasks of a lost worker on the others (its Nanny restarts it); a batch's
  rows are written once, when its result reaches the client, and Store.write drops cases already on disk.
"""
from __future__ import annotations

import contextlib
import logging
import math
import os
import signal
import threading
import time

from distributed import as_completed
from distributed.diagnostics.plugin import WorkerPlugin

from vibrofmu.study.spec import Spec, SpecError

CONNECT_TIMEOUT_S = 3.0  # --scheduler: give up connecting after this (the whole command must fail within 10 s)
OVERHEAD_PROBE_TASKS = 200
MAX_OVERHEAD = 0.05  # scheduling cost per task / work per task
BATCHES_PER_WORKER = 4
# Checkpoints: no batch holds more than about CHECKPOINT_S of work (at the pilot's cost per case), so finished cases
# reach the disk at least that often per worker and a Ctrl-C loses little; unless the scheduling overhead needs
# larger batches (needed_batch wins).
CHECKPOINT_S = 2.0
# Ctrl-C: the batches that finish within STOP_GRACE_S are still written; then the command stops (its cluster is
# closed within CLOSE_TIMEOUT_S): the whole exit takes a few seconds, whatever a batch still running costs.
STOP_GRACE_S = 1.5
CLOSE_TIMEOUT_S = 2.0

FMU_BYTES: dict[str, bytes] = {}  # per worker process: digest -> FMU bytes (filled by FmuFile)


class FmuFile(WorkerPlugin):
    """Gives every worker (also restarted or late ones) the plant FMU's bytes."""

    name = "vibrofmu-study-fmu"

    def __init__(self, digest: str, data: bytes):
        self.digest, self.data = digest, data

    def setup(self, worker):
        FMU_BYTES[self.digest] = self.data


STOP = threading.Event()


@contextlib.contextmanager
def stop_on_sigint():
    """The first Ctrl-C sets STOP: execute writes the batches that finish in the next STOP_GRACE_S and stops (no
    signal lands inside Dask's own code meanwhile, where it could be taken for a failed task); then, or at a
    second Ctrl-C, KeyboardInterrupt."""
    timers = []

    def handler(signum, frame):
        if STOP.is_set():
            raise KeyboardInterrupt
        STOP.set()
        # then a real SIGINT to the main thread (runs this handler again, STOP being set; a real signal also ends a
        # wait of the main thread, which _thread.interrupt_main does not)
        timer = threading.Timer(STOP_GRACE_S, signal.pthread_kill, (threading.main_thread().ident, signal.SIGINT))
        timer.daemon = True
        timers.append(timer)
        timer.start()

    STOP.clear()
    previous = signal.signal(signal.SIGINT, handler)
    try:
        yield
    finally:
        for timer in timers:  # stopped already: no late interrupt in what follows (writing the results)
            timer.cancel()
        signal.signal(signal.SIGINT, previous)


def noop(i):
    return i


def run_batch(spec_dict: dict, fmu_digest: str | None, cases: list[dict]) -> list[dict]:
    """A task: the rows of every case of the batch, on this worker's engine."""
    from vibrofmu.study.engines import engine_for
    from vibrofmu.study.cases import run_case

    spec = Spec(**spec_dict)
    engine = engine_for(spec.engine, FMU_BYTES.get(fmu_digest) if fmu_digest else None)
    if spec.engine == "fmu" and fmu_digest not in FMU_BYTES:
        raise RuntimeError("the FMU plugin is not installed on this worker")
    rows = []
    for case in cases:
        rows.extend(run_case(spec, engine, case))
    return rows


def warm_up(spec_dict: dict, fmu_digest: str | None) -> float:
    """Run on every worker before the study (client.run): import the study's modules and make the worker's
    engine (unpack the FMU or load the kernel), so that the pilot measures a case, not the imports, and the
    speed-up from 1 to W workers is not diluted by this fixed per-worker cost. Returns its seconds."""
    started = time.perf_counter()
    from vibrofmu.study.cases import run_case  # noqa: F401 - the import is the point
    from vibrofmu.study.engines import engine_for

    spec = Spec(**spec_dict)
    if spec.engine == "core" or fmu_digest in FMU_BYTES:
        engine_for(spec.engine, FMU_BYTES.get(fmu_digest) if fmu_digest else None)
    return time.perf_counter() - started


def quiet_dask() -> None:
    for name in ("distributed", "distributed.nanny", "distributed.scheduler", "distributed.worker",
                 "distributed.core", "distributed.comm", "tornado"):
        logging.getLogger(name).setLevel(logging.CRITICAL)


# every process spawn_without_sigint's spawns started (study.end_children ends those still ours: a child being
# spawned is not among multiprocessing's active children until its start-up data is written, and if this process
# exits meanwhile the child prints an EOFError traceback)
SPAWNED: set[int] = set()


def spawn_without_sigint() -> None:
    """From now on, every process multiprocessing spawns in this one (the local cluster's workers, its resource
    tracker) starts with SIGINT blocked: the spawning thread blocks it for the spawn call alone and the child
    inherits the mask, as multiprocessing's own resource tracker does. A Ctrl-C reaches the whole process group,
    and a worker that got it while still importing printed a KeyboardInterrupt traceback after the study's last
    line (3 of 15 interrupts); the study's own process keeps answering it (its other threads do not block it)."""
    from multiprocessing import util

    spawn = util.spawnv_passfds
    if getattr(spawn, "without_sigint", False):
        return

    def spawnv_passfds(path, args, passfds):
        old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        try:
            pid = spawn(path, args, passfds)
            SPAWNED.add(pid)
            return pid
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, old)

    spawnv_passfds.without_sigint = True
    util.spawnv_passfds = spawnv_passfds


def connect(scheduler: str | None, workers: int | None):
    """(client, cluster or None): an existing scheduler, or a LocalCluster of worker processes."""
    from distributed import Client, LocalCluster

    quiet_dask()
    if scheduler:
        try:
            client = Client(scheduler, timeout=CONNECT_TIMEOUT_S)
        except (OSError, TimeoutError) as error:
            raise SpecError(f"cannot reach the Dask scheduler at {scheduler} within {CONNECT_TIMEOUT_S:g} s "
                            f"({type(error).__name__})") from None
        except ValueError as error:
            raise SpecError(f"--scheduler {scheduler!r}: {error}") from None
        except Exception as error:  # something answered that does not speak Dask's protocol
            raise SpecError(f"--scheduler {scheduler}: not a Dask scheduler ({type(error).__name__})") from None
        try:
            client.wait_for_workers(1, timeout=CONNECT_TIMEOUT_S)
        except TimeoutError:
            client.close()
            raise SpecError(f"the Dask scheduler at {scheduler} has no workers") from None
        return client, None
    n = workers or os.cpu_count() or 1
    # Ctrl-C in a terminal reaches the whole process group: the worker processes start with SIGINT blocked
    # (spawn_without_sigint), then ignore it (worker_signals, preloaded; also in the workers a nanny restarts), and
    # the client answers it: it keeps every finished case and ends the workers (study.run)
    spawn_without_sigint()
    cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, host="127.0.0.1",
                           dashboard_address=None, silence_logs=logging.CRITICAL,
                           preload=["vibrofmu.study.worker_signals"])
    return Client(cluster), cluster


def scheduler_cost(client, n: int = OVERHEAD_PROBE_TASKS) -> float:
    """Seconds of scheduling per task: wall time of n empty tasks (after a warm-up round) over n. With the
    scheduler handling one task at a time this is its cost per task, client round trip included."""
    client.gather(client.map(noop, range(20), pure=False))
    started = time.perf_counter()
    client.gather(client.map(noop, range(n), pure=False))
    return (time.perf_counter() - started) / n


def needed_batch(c_s: float, c_w: float, workers: int) -> int:
    """Smallest b with c_s / (b c_w) <= MAX_OVERHEAD (a worker's share) and b / c_s >= workers / c_w (the one
    scheduler, handing out a task per c_s, keeps every worker busy)."""
    if not c_w > 0:
        return 1
    return max(1, math.ceil(c_s / (MAX_OVERHEAD * c_w)), math.ceil(workers * c_s / c_w))


def batch_size(c_s: float, c_w: float, remaining: int, workers: int) -> int:
    """The smallest batch size: needed_batch, but no more than a BATCHES_PER_WORKER-th of each worker's share."""
    balance = max(1, remaining // (BATCHES_PER_WORKER * workers))
    return max(1, min(needed_batch(c_s, c_w, workers), balance))


def checkpoint_batch(c_w: float) -> int | None:
    """The largest batch that holds about CHECKPOINT_S of work at c_w seconds a case (at least 1; None: no cost
    measured, no cap)."""
    return max(1, int(CHECKPOINT_S / c_w)) if c_w > 0 else None


def guided_batches(n: int, smallest: int, workers: int, largest: int | None = None) -> list[int]:
    """Batch sizes for n cases, largest first (guided self-scheduling): each batch takes a
    BATCHES_PER_WORKER * workers-th of the cases still left, but at least `smallest`. Few, large batches at the
    start keep the client's work per batch (a Parquet part, a progress update, a scheduler round trip) small; the
    small ones at the end let the workers finish together (the idle tail is about one small batch). `largest`
    (checkpoint_batch) caps them, so that finished cases reach the disk every few seconds."""
    sizes, left = [], n
    cap = math.inf if largest is None else max(smallest, largest)  # (the overhead's smallest wins)
    while left > 0:
        size = min(left, cap, max(smallest, math.ceil(left / (BATCHES_PER_WORKER * workers))))
        sizes.append(size)
        left -= size
    return sizes


class Progress:
    """tqdm bar on stderr: cases done (resumed ones counted from the start), rate and ETA of this run."""

    def __init__(self, total: int, done: int, label: str):
        from tqdm import tqdm

        self.bar = tqdm(total=total, initial=done, unit="case", desc=label, mininterval=0.5, smoothing=0.1,
                        dynamic_ncols=True)

    def update(self, n: int) -> None:
        self.bar.update(n)

    def close(self) -> None:
        self.bar.close()


def execute(client, spec: Spec, cases: list[dict], store, fmu_digest: str | None, progress: Progress) -> dict:
    """Run every case not on disk; write each batch's rows as it arrives. Returns the run's measurements."""
    n_workers = max(1, len(client.scheduler_info(n_workers=-1)["workers"]))
    spec_dict = spec.as_dict()
    warm = time.perf_counter()
    try:
        warm_ups = client.run(warm_up, spec_dict, fmu_digest)
    except Exception:  # noqa: BLE001 - a worker lost meanwhile: it warms up in its first task instead
        warm_ups = {}
    warm = time.perf_counter() - warm
    c_s = scheduler_cost(client)
    todo = [case for case in cases if case["case"] not in store.written]
    started = time.perf_counter()
    tally = {"cases": 0, "cost": 0.0}
    failures = []

    # the pilot: one case per worker; as soon as the first one is back (its cost is c_w), the rest go out in
    # batches while the other pilot cases still run (no worker waits for the slowest pilot case)
    pilot, rest = todo[:n_workers], todo[n_workers:]
    futures = client.map(run_batch, [spec_dict] * len(pilot), [fmu_digest] * len(pilot), [[c] for c in pilot],
                         pure=False)
    pending = as_completed(futures)
    plan = {"b": 1, "sizes": []}

    def submit_rest():
        c_w = tally["cost"] / tally["cases"] if tally["cases"] else 0.0
        plan["c_w"] = c_w
        plan["b"] = b = batch_size(c_s, c_w, len(rest), n_workers)
        plan["sizes"] = sizes = guided_batches(len(rest), b, n_workers, checkpoint_batch(c_w))
        starts = [sum(sizes[:k]) for k in range(len(sizes))]
        batches = [rest[start:start + size] for start, size in zip(starts, sizes)]
        more = client.map(run_batch, [spec_dict] * len(batches), [fmu_digest] * len(batches), batches, pure=False)
        futures.extend(more)
        pending.update(more)

    submitted = not rest  # (no pilot means no cases at all)
    for future in pending:
        try:
            rows = future.result()
        except Exception as error:  # a batch that failed (e.g. its worker died too often): not written
            failures.append(f"{type(error).__name__}: {error}")
            rows = []
        tally["cases"] += len({row["case"] for row in rows})
        tally["cost"] += sum(row["cost_s"] for row in rows)
        progress.update(store.write(rows))
        if STOP.is_set():  # Ctrl-C (stop_on_sigint): the batch in hand is written; stop, keep what is written
            client.cancel(futures)
            raise KeyboardInterrupt
        if not submitted:
            submitted = True
            submit_rest()
    b, c_w = plan["b"], plan.get("c_w", 0.0)
    batches = plan["sizes"]
    wall = time.perf_counter() - started
    done = tally["cases"]
    per_case = tally["cost"] / done if done else math.nan
    return {"workers": n_workers, "scheduler_s_per_task": c_s, "pilot_case_cost_s": c_w, "batch_size": b,
            "batches": len(batches) + len(pilot), "batch_sizes": batches,
            "expected_overhead_fraction": c_s / (b * c_w) if c_w else math.nan,
            "warm_up_wall_s": warm, "warm_up_s_per_worker": sorted(warm_ups.values()),
            "compute_wall_s": wall, "case_cost_s_mean": per_case, "case_cost_s_sum": tally["cost"],
            # every worker-second not spent inside a case, per case: scheduling, transfers, writing, the
            # pilot's wait and the idle tail
            "overhead_s_per_case": (n_workers * wall - tally["cost"]) / done if done else math.nan,
            "failed_batches": failures, "computed": done}
