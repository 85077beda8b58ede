"""Issue 23, item 3: `vibrofmu build` says in one line when it builds the native FMUs without win64 binaries, and
why (mingw-w64 missing); with mingw-w64 on PATH it says nothing about win64."""
from __future__ import annotations

import shutil

import pytest

from vibrofmu.commands.common import say_compiled_parts
from vibrofmu.fmus import toolchain


def _path_with(tmp_path, *programs) -> str:
    """A PATH holding only links to these programs."""
    folder = tmp_path / "bin"
    folder.mkdir()
    for program in programs:
        (folder / program).symlink_to(shutil.which(program))
    return str(folder)


def test_build_says_in_one_line_that_it_skips_win64(tmp_path, monkeypatch, capsys):
    monkeypatch.delenv("CC", raising=False)
    monkeypatch.setenv("PATH", _path_with(tmp_path, "gcc"))  # a C compiler, no mingw-w64
    say_compiled_parts(natives=True)
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1, lines
    assert lines[0].startswith("warning: ") and toolchain.WIN64_COMPILER in lines[0] and "win64" in lines[0]
    assert "apt-get install gcc-mingw-w64-x86-64" in lines[0]


@pytest.mark.tools("x86_64-w64-mingw32-gcc")
def test_build_says_nothing_of_win64_with_mingw(tmp_path, monkeypatch, capsys):
    monkeypatch.delenv("CC", raising=False)
    monkeypatch.setenv("PATH", _path_with(tmp_path, "gcc", toolchain.WIN64_COMPILER))
    say_compiled_parts(natives=True)
    assert capsys.readouterr().err == ""


def test_the_plant_alone_says_nothing_of_win64(tmp_path, monkeypatch, capsys):
    """Commands that build the plant only (no native FMU) do not mention win64."""
    monkeypatch.delenv("CC", raising=False)
    monkeypatch.setenv("PATH", _path_with(tmp_path, "gcc"))
    say_compiled_parts()
    assert capsys.readouterr().err == ""
