"""The README's Python snippets run as a user runs them: from a folder whose build/ holds the three FMUs (the
snippets name build/...), in a fresh interpreter, without an error, printing what they say they print."""
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SNIPPET = re.compile(r"```python\n(.*?)```", re.S)


def snippets():
    return SNIPPET.findall((ROOT / "README.md").read_text())


def test_the_readme_has_an_fmpy_snippet_for_each_fmu():
    text = "\n".join(snippets())
    for name in ("HertzEAOscillator.fmu", "AdaptiveLyapunovController.fmu", "HertzEAClosedLoop.fmu"):
        assert f"build/{name}" in text


@pytest.mark.fmu
@pytest.mark.parametrize("code", snippets(), ids=lambda code: code.splitlines()[0][:40])
def test_readme_snippet_runs(code, plant_fmu, controller_fmu, closed_loop_fmu, tmp_path):
    assert plant_fmu.parent == controller_fmu.parent == closed_loop_fmu.parent
    (tmp_path / "build").symlink_to(plant_fmu.parent, target_is_directory=True)
    proc = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    printed = proc.stdout.splitlines()
    assert len(printed) == code.count("print("), proc.stdout  # every print ran
    for line in printed:  # and printed a finite number
        value = float(line.rsplit(" ", 1)[-1])
        assert value == value and abs(value) < 1.0, line
