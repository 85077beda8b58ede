"""The bench's child processes (C hosts, valgrind, fresh Pythons, peers' drivers), run like subprocess.run but in a
session of their own: a Ctrl-C in the terminal reaches the bench alone, which kills the child at once and stops.
In the terminal's process group the child got the SIGINT too, and subprocess waited for it to end by itself: a
host under valgrind then wrote its profile first (1.17 s from Ctrl-C to the bench's exit at load 8)."""
from __future__ import annotations

import subprocess


def run(cmd, *, capture_output: bool = False, timeout: float | None = None, check: bool = False,
        **kwargs) -> subprocess.CompletedProcess:
    """subprocess.run(cmd, capture_output=..., timeout=..., check=..., **kwargs) in a new session; on any exception
    in the waiting (KeyboardInterrupt, the timeout) the child is killed before it propagates."""
    if capture_output:
        kwargs["stdout"] = kwargs["stderr"] = subprocess.PIPE
    with subprocess.Popen(cmd, start_new_session=True, **kwargs) as process:
        # the child never sees our SIGINT: Popen's grace period for a child that got it too (0.25 s) is not needed
        process._sigint_wait_secs = 0.0
        try:
            stdout, stderr = process.communicate(timeout=timeout)
        except BaseException:
            process.kill()
            raise
        code = process.poll()
    if check and code:
        raise subprocess.CalledProcessError(code, cmd, stdout, stderr)
    return subprocess.CompletedProcess(cmd, code, stdout, stderr)
