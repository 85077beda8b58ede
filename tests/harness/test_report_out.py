"""`vibrofmu report --quick` and `--from` never rewrite the published documents: they write the documents with the
regenerated blocks to a folder (--out, default out/report); `--out` onto the documents themselves is refused in one
line; `--check` names the blocks it does not compare, and compares the cascade's and the cusp study's numbers but not
their CPU times. The blocks are stand-ins (report.generate patched) or made from stored outputs of the two studies
(tests/data/report_studies), and the FMUs stand-in archives: no FMU or study runs here."""
from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path

import pytest
from test_cli import stand_in_checkout

from vibrofmu.cli import main

BLOCK = "<!-- report:ranges -->\ngenerated ranges table\n<!-- /report:ranges -->"
PUBLISHED = (("oafm", "model.md"), ("stability", "numerics.md"), ("cascade", "continuation.md"),
             ("cusp_order", "continuation.md"), ("curve_speed", "continuation.md"),
             ("auto", "rungs.md"))  # the summary blocks --check compares, and where they are


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
    published = {name: report.parse_blocks((root / "docs" / doc).read_text())[name] for name, doc in PUBLISHED}
    monkeypatch.setattr(report, "generate", lambda names, *args: {"ranges": "generated ranges table\n", **published})
    studies = []  # the studies --check runs for the summary blocks (stand-ins: no study runs)
    monkeypatch.setattr(command, "run_studies", lambda *args: studies.append(args[-1]) or [])
    assert main(["report", "--check", "--root", str(root), "--fmu-dir", str(fmus)]) == 0
    out = capsys.readouterr().out
    assert "blocks auto, cascade, curve_speed, cusp_order, oafm, ranges, stability match a fresh run" in out
    assert "not compared: machine (" in out and "speed (timings and instruction counts" in out
    assert "peers (timings of other ODE solvers" in out
    for name in ("cascade", "cusp_order", "curve_speed", "auto"):  # compared: not in the list of those that are not
        assert f"{name} (" not in out
    # without --from: fresh full runs of the studies, the curve's bench and the auto replay, never the full bench
    assert studies == [("oafm", "stability", "cascade", "cusp_order", "curve_speed", "auto")]
    assert digests(root) == before


def test_check_compares_the_oafm_and_stability_blocks(stand_ins, monkeypatch, capsys):
    """Plain --check (no --from) regenerates the oafm and stability blocks too: a differing one fails, named."""
    import vibrofmu.commands.report as command
    import vibrofmu.report as report

    root, fmus = stand_ins
    published = {name: report.parse_blocks((root / "docs" / doc).read_text())[name] for name, doc in PUBLISHED}
    monkeypatch.setattr(report, "DETERMINISTIC", ())
    monkeypatch.setattr(command, "run_studies", lambda *args: [])
    for body, code in ((published["oafm"], 0), (published["oafm"].replace("|", "¦", 1), 1)):
        monkeypatch.setattr(report, "generate", lambda names, *args, body=body: {**published, "oafm": body})
        assert main(["report", "--check", "--root", str(root), "--fmu-dir", str(fmus)]) == code
        captured = capsys.readouterr()
        if code:
            assert "docs/model.md: oafm" in captured.err and captured.err.startswith("error:")
        else:
            assert "blocks auto, cascade, curve_speed, cusp_order, oafm, stability match a fresh run" in captured.out


def test_check_refuses_quick(stand_ins, capsys):
    root, fmus = stand_ins
    assert main(["report", "--check", "--quick", "--root", str(root), "--fmu-dir", str(fmus)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: --quick") and len(err.splitlines()) == 1


STORED = Path(__file__).resolve().parents[1] / "data" / "report_studies"  # outputs of the documented studies
FILES = {"cascade": "summary.json", "cusp_order": "cusp_order.json", "curve_speed": "bench.json",
         "auto": "auto_replay.json"}  # what --check's run of each study writes (auto: error_calibration.auto_replay)
# auto: the documents' block comes from a campaign (error_calibration.auto_campaign 6 7, auto.json; docs/rungs.md's
# is 500 7), which --check's run does not repeat: it replays the same pairs (auto_replay 6 7, the stored output)
CAMPAIGN = STORED / "auto_campaign"


@pytest.fixture
def studied(tmp_path, monkeypatch):
    """A copy of the documents whose cascade, cusp_order, curve_speed and auto blocks are made from the stored study
    outputs (auto's from the stored campaign); --check compares those blocks only, the studies' runs replaced by
    copies of the stored outputs (`runs`: the studies --check asked for). Returns (root, fmus, {block: its study's
    folder}, runs)."""
    import vibrofmu.commands.report as command
    import vibrofmu.report as report

    root, fmus = stand_in_checkout(tmp_path)
    shutil.copytree(STORED, tmp_path / "studies")
    folders = {name: tmp_path / "studies" / name for name in FILES}
    for doc in (root / "docs" / "continuation.md", root / "docs" / "rungs.md"):
        doc.write_text(report.replace_blocks(doc.read_text(), {
            name: report.summary_block(name, [CAMPAIGN if name == "auto" else folder])
            for name, folder in folders.items()}))
    monkeypatch.setattr(report, "DETERMINISTIC", ())
    monkeypatch.setattr(command, "FROM_CHECKED", tuple(FILES))
    runs = []
    monkeypatch.setattr(command, "run_studies", lambda *args: runs.append(args[-1]) or [folders[s] for s in args[-1]])
    return root, fmus, folders, runs


def _shift(path, factor=1.0, offset=0.0):
    """A change of the study output at `path` (keys and indices): value * factor + offset."""
    def change(data):
        *head, last = path
        for key in head:
            data = data[key]
        data[last] = data[last] * factor + offset
    return change


# (the study, a change of its output, whether --check must see it); each deterministic change is larger than the
# last digit the block prints of that number (10 decimals for a doubling point, 6 for a multiplier, 4 for a ratio,
# 10 significant digits for a cusp's Delta, 12 decimals for its omega, 3 decimals for an order), so it shows
CHANGES = [("cascade", lambda data: None, False),
           ("curve_speed", _shift(("curve", "cpu_seconds"), 40.0, 7.0), False),  # timings, the machine and its load
           ("curve_speed", _shift(("curve", "seconds"), 40.0, 7.0), False),
           ("curve_speed", _shift(("curve", "cpu_seconds_per_point"), 40.0), False),
           ("curve_speed", _shift(("curve", "load_average_at_start", 0), offset=9.0), False),
           ("curve_speed", _shift(("curve", "cpu_count"), offset=6), False),
           ("curve_speed", _shift(("curve", "points"), offset=1), True),
           # |P(z) - z| and |det(M - I)| print 2 significant digits: a 10 % change shows
           ("curve_speed", _shift(("curve", "fold_system", "max_residual"), factor=1.1), True),
           ("curve_speed", _shift(("curve", "fold_system", "max_det"), factor=1.1), True),
           ("curve_speed", _shift(("curve", "fold_system", "points"), offset=-1), True),
           ("auto", _shift(("rows", 2, "met"), factor=0), True),  # a pair auto's choice no longer meets
           ("auto", lambda data: data["rows"][1].update(chosen="fidelity 3"), True),
           ("auto", _shift(("summary", "refused"), offset=1), True),
           ("auto", _shift(("summary", "compared_run"), offset=-1), True),
           ("cascade", _shift(("cpu_seconds",), 40.0, 7.0), False),  # the CPU time: depends on the machine
           ("cascade", _shift(("cascade", "doublings", 2, "value"), offset=2e-10), True),
           ("cascade", _shift(("cascade", "doublings", 4, "multipliers", 0, 0), offset=2e-6), True),
           ("cascade", _shift(("cascade", "ratios", 1), offset=2e-4), True),
           ("cascade", _shift(("points",), offset=1), True),
           ("cusp_order", _shift(("cpu_seconds",), 40.0, 7.0), False),
           ("cusp_order", _shift(("rows", 3, "exact_Delta"), factor=1 + 2e-9), True),
           ("cusp_order", _shift(("rows", 5, "slow_omega"), offset=2e-12), True),
           ("cusp_order", _shift(("orders", "Delta", "order"), offset=2e-3), True),
           ("cusp_order", _shift(("orders", "omega", "local", 2), offset=2e-2), True)]


@pytest.mark.parametrize("study, change, seen", CHANGES, ids=[
    "cascade-as-stored", "curve-cpu-time", "curve-wall-clock", "curve-per-point", "curve-load", "curve-cpus",
    "curve-points", "curve-residual", "curve-det", "curve-checked-points", "auto-met", "auto-choice", "auto-refused",
    "auto-compared", "cascade-cpu-time", "doubling-point", "multiplier", "ratio", "points", "cusp-cpu-time",
    "exact-cusp-Delta", "slow-flow-omega", "order", "local-order"])
def test_check_compares_the_cascade_and_cusp_numbers_not_their_cpu_times(studied, capsys, study, change, seen):
    root, fmus, folders, runs = studied
    file = folders[study] / FILES[study]
    data = json.loads(file.read_text())
    change(data)
    file.write_text(json.dumps(data))
    code = main(["report", "--check", "--root", str(root), "--fmu-dir", str(fmus)])
    captured = capsys.readouterr()
    assert runs == [tuple(FILES)]  # every study run again (stand-ins here), never read from the docs
    errors = [line for line in captured.err.splitlines() if line.startswith("error:")]
    if seen:  # one error line naming the changed block, and only it
        assert code == 1 and len(errors) == 1 and errors[0].startswith("error: generated numbers differ")
        doc = "rungs.md" if study == "auto" else "continuation.md"
        assert f"docs/{doc}: {study}" in errors[0]
        assert not any(f": {other}" in errors[0] for other in FILES if other != study)
    else:
        assert code == 0 and not errors, captured.err
        assert f"blocks {', '.join(sorted(FILES))} match a fresh run" in captured.out


def test_check_runs_only_the_studies_the_from_folders_lack(studied, capsys):
    """With --from a folder holding the cascade's summary, --check compares the cascade from it and runs the cusp
    study alone; a changed doubling point in that summary fails the check."""
    root, fmus, folders, runs = studied
    argv = ["report", "--check", "--from", str(folders["cascade"]), "--root", str(root), "--fmu-dir", str(fmus)]
    assert main(argv) == 0
    assert runs == [("cusp_order", "curve_speed", "auto")]
    file = folders["cascade"] / FILES["cascade"]
    data = json.loads(file.read_text())
    data["cascade"]["doublings"][0]["value"] += 1e-8
    file.write_text(json.dumps(data))
    assert main(argv) == 1
    assert "docs/continuation.md: cascade" in capsys.readouterr().err
