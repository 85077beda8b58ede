"""The bench's child processes (vibrofmu.speed.child.run): subprocess.run's results, but in a session of their
own, so that a Ctrl-C in the terminal reaches the bench alone, and killed (and reaped) when the wait is cut short."""
import os
import subprocess
import sys
from pathlib import Path

import pytest

from vibrofmu.speed import child

pytestmark = pytest.mark.fast


def test_results_as_subprocess_run():
    code = "import sys; print('out'); print('err', file=sys.stderr); sys.exit(3)"
    done = child.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert (done.returncode, done.stdout, done.stderr) == (3, "out\n", "err\n")
    with pytest.raises(subprocess.CalledProcessError):
        child.run([sys.executable, "-c", code], capture_output=True, check=True)


def test_a_session_of_its_own():
    """Not in the terminal's process group: the terminal's SIGINT does not reach it."""
    done = child.run([sys.executable, "-c", "import os; print(os.getsid(0), os.getpgid(0))"], capture_output=True,
                     text=True)
    sid, pgid = map(int, done.stdout.split())
    assert sid != os.getsid(0) and pgid != os.getpgid(0)


def test_killed_and_reaped_when_the_wait_is_cut_short(tmp_path):
    """The wait ends early (here its timeout; a KeyboardInterrupt takes the same path): the child is gone before the
    exception reaches the caller, not left running in its own session."""
    pid_file = tmp_path / "pid"
    code = f"import os, time; open({str(pid_file)!r}, 'w').write(str(os.getpid())); time.sleep(600)"
    with pytest.raises(subprocess.TimeoutExpired):
        child.run([sys.executable, "-c", code], timeout=5)
    pid = int(pid_file.read_text())
    assert not Path(f"/proc/{pid}").exists()
