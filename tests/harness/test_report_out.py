"""`vibrofmu report --quick` and `--from` never rewrite the published documents: they write the documents with the
regenerated blocks to a folder (--out, default out/report); `--out` onto the documents themselves is refused in one
line; `--check` names the blocks it does not compare. The blocks are stand-ins (report.generate patched) and the
FMUs stand-in archives: no FMU runs here."""
from __future__ import annotations

import hashlib
from pathlib import Path

import pytest
from test_cli import stand_in_checkout

from vibrofmu.cli import main

BLOCK = "<!-- report:ranges -->\ngenerated ranges table\n<!-- /report:ranges -->"


def digests(folder: Path) -> dict:
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture
def stand_ins(tmp_path, monkeypatch):
    """(a copy of the documents, a folder of stand-in FMUs); report.generate gives the ranges block only."""
    import vibrofmu.report as report

    root, fmus = stand_in_checkout(tmp_path)
    monkeypatch.setattr(report, "generate", lambda names, *args: {"ranges": "generated ranges table\n"})
    monkeypatch.chdir(tmp_path)
    return root, fmus


@pytest.mark.parametrize("extra", [["--quick"], ["--from", "{summaries}"]], ids=["quick", "from"])
def test_quick_and_from_write_a_folder_not_the_documents(stand_ins, tmp_path, capsys, extra):
    root, fmus = stand_ins
    (tmp_path / "summaries").mkdir()
    extra = [arg.format(summaries=tmp_path / "summaries") for arg in extra]
    before = digests(root)
    assert main(["report", "--only", "ranges", *extra, "--root", str(root), "--fmu-dir", str(fmus)]) == 0
    assert digests(root) == before  # the published documents untouched
    out = tmp_path / "out" / "report"  # the default folder, under the working folder
    assert sorted(digests(out)) == ["README.md", *sorted(f"docs/{p.name}" for p in (root / "docs").glob("*.md"))]
    assert BLOCK in (out / "docs" / "robustness.md").read_text()
    assert "wrote out/report/docs/robustness.md: ranges" in capsys.readouterr().out  # the folder as given


def test_out_onto_the_documents_is_refused(stand_ins, capsys):
    root, fmus = stand_ins
    before = digests(root)
    assert main(["report", "--quick", "--out", str(root), "--root", str(root), "--fmu-dir", str(fmus)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: --out") and "would rewrite the documents" in err and len(err.splitlines()) == 1
    assert digests(root) == before


def test_a_full_run_still_rewrites_the_documents(stand_ins, capsys):
    root, fmus = stand_ins
    assert main(["report", "--only", "ranges", "--root", str(root), "--fmu-dir", str(fmus)]) == 0
    assert BLOCK in (root / "docs" / "robustness.md").read_text()
    assert not (Path.cwd() / "out").exists()


def test_check_names_the_blocks_it_does_not_compare(stand_ins, monkeypatch, capsys):
    import vibrofmu.commands.report as command
    import vibrofmu.report as report

    root, fmus = stand_ins
    robustness = root / "docs" / "robustness.md"
    text = robustness.read_text()
    start, end = text.index("<!-- report:ranges -->"), text.index("<!-- /report:ranges -->")
    robustness.write_text(text[:start] + BLOCK + text[end + len("<!-- /report:ranges -->"):])
    before = digests(root)
    monkeypatch.setattr(report, "DETERMINISTIC", ("ranges",))
    published = {name: report.parse_blocks((root / "docs" / doc).read_text())[name]
                 for name, doc in (("oafm", "model.md"), ("stability", "numerics.md"))}
    monkeypatch.setattr(report, "generate", lambda names, *args: {"ranges": "generated ranges table\n", **published})
    studies = []  # the studies --check runs for the oafm and stability blocks (stand-ins: no study runs)
    monkeypatch.setattr(command, "run_studies", lambda *args: studies.append(args[-1]) or [])
    assert main(["report", "--check", "--root", str(root), "--fmu-dir", str(fmus)]) == 0
    out = capsys.readouterr().out
    assert "blocks oafm, ranges, stability match a fresh run" in out
    assert "not compared: machine (" in out and "speed (timings and instruction counts" in out
    assert "peers (timings of other ODE solvers" in out
    assert studies == [("oafm", "stability")]  # without --from: fresh full runs of both, never the bench
    assert digests(root) == before


def test_check_compares_the_oafm_and_stability_blocks(stand_ins, monkeypatch, capsys):
    """Plain --check (no --from) regenerates the oafm and stability blocks too: a differing one fails, named."""
    import vibrofmu.commands.report as command
    import vibrofmu.report as report

    root, fmus = stand_ins
    published = {name: report.parse_blocks((root / "docs" / doc).read_text())[name]
                 for name, doc in (("oafm", "model.md"), ("stability", "numerics.md"))}
    monkeypatch.setattr(report, "DETERMINISTIC", ())
    monkeypatch.setattr(command, "run_studies", lambda *args: [])
    for body, code in ((published["oafm"], 0), (published["oafm"].replace("|", "¦", 1), 1)):
        monkeypatch.setattr(report, "generate", lambda names, *args, body=body: {"oafm": body,
                                                                                  "stability": published["stability"]})
        assert main(["report", "--check", "--root", str(root), "--fmu-dir", str(fmus)]) == code
        captured = capsys.readouterr()
        if code:
            assert "docs/model.md: oafm" in captured.err and captured.err.startswith("error:")
        else:
            assert "blocks oafm, stability match a fresh run" in captured.out


def test_check_refuses_quick(stand_ins, capsys):
    root, fmus = stand_ins
    assert main(["report", "--check", "--quick", "--root", str(root), "--fmu-dir", str(fmus)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: --quick") and len(err.splitlines()) == 1
