"""The C compilers of a build as child processes that run side by side and stop together.

`run(cmd)` runs one compiler and returns subprocess.run's result. `in_parallel(steps)` runs build steps (each
calls `run`) in threads, one per core. When a step fails or the user presses Ctrl-C, every compiler still
running is killed and no new one starts. Each step then fails at once, its staging folder is removed by its
own `with` block, and the build ends within a moment. A half-built file is never left under its final name
(archive.staging and archive.publish). Standard library only.
"""
from __future__ import annotations

import os
import subprocess
import threading
from concurrent.futures import FIRST_EXCEPTION, ThreadPoolExecutor, wait

_lock = threading.Lock()
_running: set[subprocess.Popen] = set()
_stopped = threading.Event()


class Stopped(RuntimeError):
    """A compiler was not started: the build is stopping (another step failed, or Ctrl-C)."""


def run(cmd: list[str]) -> subprocess.CompletedProcess:
    """Run the compiler command `cmd` (output captured, as text); Stopped if the build is stopping."""
    with _lock:
        if _stopped.is_set():
            raise Stopped("the build is stopping: a compiler was not started")
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        _running.add(proc)
    try:
        out, err = proc.communicate()
    except BaseException:  # Ctrl-C in the thread that waits (the serial build): the compiler goes too
        proc.kill()
        proc.wait()
        raise
    finally:
        with _lock:
            _running.discard(proc)
    return subprocess.CompletedProcess(cmd, proc.returncode, out, err)


def running() -> int:
    """How many compilers are running now."""
    with _lock:
        return len(_running)


def stop() -> None:
    """Kill every compiler running and start no new one (until the current in_parallel ends)."""
    with _lock:
        _stopped.set()
        for proc in _running:
            proc.kill()


def in_parallel(steps, workers: int | None = None) -> list:
    """[step() for step in steps], run in up to `workers` threads (default: the cores); the first failure (or
    KeyboardInterrupt) stops the other steps' compilers and is raised once every thread has ended."""
    steps = list(steps)
    workers = min(len(steps), workers or os.cpu_count() or 1)
    if workers <= 1:
        return [step() for step in steps]
    pool = ThreadPoolExecutor(workers, thread_name_prefix="vibrofmu-build")
    try:
        futures = [pool.submit(step) for step in steps]
        wait(futures, return_when=FIRST_EXCEPTION)
        failed = next((f for f in futures if f.done() and not f.cancelled() and f.exception()), None)
        if failed is not None:
            stop()
            raise failed.exception()
        return [future.result() for future in futures]
    except BaseException:
        stop()
        raise
    finally:
        pool.shutdown(wait=True, cancel_futures=True)  # quick: the compilers are gone, their steps fail
        _stopped.clear()
