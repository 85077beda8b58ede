"""fmus.compilers: the native FMUs' compilers run side by side, and a failing step (or Ctrl-C) stops the others at
once, so that a parallel build ends as quickly as a serial one and leaves nothing running."""
import sys
import time

import pytest

from vibrofmu.fmus import compilers

# A stand-in compiler that would run for a minute and then return 0: one that was stopped returns the signal's
# negative number instead (checked below), and none is left running.
LONG = [sys.executable, "-c", "import time; time.sleep(60)"]


def test_results_come_back_in_the_order_of_the_steps():
    steps = [lambda k=k: compilers.run([sys.executable, "-c", f"print({k})"]).stdout.strip() for k in range(5)]
    assert compilers.in_parallel(steps, workers=2) == [str(k) for k in range(5)]


def test_a_failing_step_kills_the_compilers_still_running_and_starts_no_more():
    started = []

    def long_step():
        proc = compilers.run(LONG)
        started.append(proc.returncode)
        return proc.returncode

    def failing_step():
        time.sleep(0.5)  # the long step's compiler is running by then
        raise RuntimeError("compiling X failed")

    with pytest.raises(RuntimeError, match="compiling X failed"):
        compilers.in_parallel([long_step, failing_step, long_step], workers=2)
    # every compiler that started was killed (a negative return code: a signal; one whose minute of sleep ran out
    # returns 0): the first long step's, and the third's if the failing step's thread took it up before the failure
    # was seen (else it was cancelled or raised Stopped). No clock is read: a loaded machine cannot fail this.
    assert started and all(code < 0 for code in started), started
    assert compilers.running() == 0
    # the next build starts afresh
    assert compilers.in_parallel([lambda: compilers.run([sys.executable, "-c", "print(1)"]).returncode] * 2) == [0, 0]
