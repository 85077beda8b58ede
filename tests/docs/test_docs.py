"""README.md and docs/*.md: every link stays inside the repository and resolves (file, and anchor if any); the
generated blocks (<!-- report:NAME --> markers) are well-formed and filled; the deterministic ones equal a fresh
`vibrofmu report --check` run."""
import re
from pathlib import Path

import pytest

from vibrofmu import report
from vibrofmu.cli import main

ROOT = Path(__file__).resolve().parents[2]
DOCS = report.documents(ROOT)
LINK = re.compile(r"(?<!!)\[[^\]]*\]\(([^)\s]+)\)")
PLACEHOLDER = "(run `vibrofmu report"


def slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces to hyphens."""
    text = re.sub(r"[`*_]", "", heading.strip().lower())
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def anchors(path: Path) -> set[str]:
    text = re.sub(r"```.*?```", "", path.read_text(), flags=re.S)
    return {slug(m.group(1)) for m in re.finditer(r"^#{1,6}\s+(.*)$", text, re.M)}


def links():
    for doc in DOCS:
        text = re.sub(r"```.*?```", "", doc.read_text(), flags=re.S)
        for target in LINK.findall(text):
            yield doc, target


def test_documents_exist():
    names = {d.relative_to(ROOT).as_posix() for d in DOCS}
    assert {"README.md", "docs/model.md", "docs/numerics.md", "docs/fmu-reference.md",
            "docs/architecture.md"} <= names


def test_slug_matches_github():
    assert slug("The plant (`HertzEAOscillator.fmu`)") == "the-plant-hertzeaoscillatorfmu"
    assert slug("Fidelity 4: the OAFM analytic solution") == "fidelity-4-the-oafm-analytic-solution"


@pytest.mark.parametrize("doc,target", list(links()), ids=lambda v: str(v)[-40:])
def test_link_resolves_inside_the_repository(doc, target):
    assert not re.match(r"^[a-z][a-z0-9+.-]*:", target, re.I), f"{doc.name}: link leaves the repository: {target}"
    path, _, anchor = target.partition("#")
    file = (doc.parent / path).resolve() if path else doc
    assert file.is_file(), f"{doc.name}: no file {path}"
    assert ROOT in file.parents, f"{doc.name}: {path} is outside the repository"
    if anchor:
        assert file.suffix == ".md" and anchor in anchors(file), f"{doc.name}: no heading #{anchor} in {file.name}"


def test_no_reference_to_material_outside_the_repository():
    for doc in DOCS:
        text = doc.read_text()
        for word in ("../shared", "ERRATA", "PAPER.md", "DESIGN.md", "issue 6", "issue 1"):
            assert word not in text, f"{doc.name} mentions {word}"


def test_no_issue_numbers_in_the_user_documents():
    """Users cannot see the project's issue tracker: the documents say what changed in their own words."""
    for doc in DOCS:
        found = re.findall(r"\bissues? #?\d+", doc.read_text(), flags=re.I)
        assert not found, f"{doc.relative_to(ROOT)}: {found}"


def test_report_blocks_are_well_formed_and_filled():
    seen = {}
    for doc in DOCS:
        for name, body in report.parse_blocks(doc.read_text(), doc.name).items():
            seen[name] = doc.name
            if name not in report.FROM_SUMMARIES:  # filled from bench/oafm/stability summaries (`report --from`)
                assert PLACEHOLDER not in body and body.strip(), f"{doc.name}: block {name} not generated"
    assert set(report.DETERMINISTIC) | {"machine"} <= set(seen)


def test_parse_blocks_rejects_malformed_markers():
    with pytest.raises(report.ReportError):
        report.parse_blocks("<!-- report:accuracy -->\nx\n")
    with pytest.raises(report.ReportError):
        report.parse_blocks("<!-- report:nonsense -->\nx\n<!-- /report:nonsense -->")
    body = "<!-- report:ssp -->\nold\n<!-- /report:ssp -->"
    assert report.replace_blocks(body, {"ssp": "new"}) == "<!-- report:ssp -->\nnew\n<!-- /report:ssp -->"


def test_check_compares_every_block_or_says_why_not():
    """`report --check` covers every block: each is compared (deterministic, or from fresh oafm/stability runs) or
    listed with the reason it is not (what depends on the machine, or the campaigns of an hour)."""
    from vibrofmu.commands.report import FROM_CHECKED, NOT_CHECKED

    compared = set(report.DETERMINISTIC) | set(FROM_CHECKED)
    assert not compared & set(NOT_CHECKED)
    assert compared | set(NOT_CHECKED) == set(report.NAMES)


def test_every_block_not_compared_says_which_of_its_numbers_depend_on_the_machine():
    """A block --check leaves out says so itself, naming what depends on the machine (and what does not), unless
    its first scenes are replayed and compared (the calibration campaigns: calibration_replay)."""
    from vibrofmu.commands.report import NOT_CHECKED

    blocks = {name: body for doc in DOCS for name, body in report.parse_blocks(doc.read_text()).items()}
    for name in NOT_CHECKED:
        said = "depend on the machine and its load (so" if name == "machine" else "depend on the machine (so"
        assert (f"{said} `vibrofmu report --check` does not compare this block)" in blocks[name].lower()
                or f"{name}_replay" in report.DETERMINISTIC), name


def test_the_cpu_time_is_the_only_number_check_leaves_out_of_the_study_blocks():
    """The cascade and cusp_order blocks say their CPU time depends on the machine, and that number alone is
    masked for --check (report.MACHINE_NUMBERS matches once; the masked text differs from the block only there)."""
    blocks = report.parse_blocks((ROOT / "docs" / "continuation.md").read_text())
    for name, pattern in report.MACHINE_NUMBERS.items():
        body = blocks[name]
        assert len(pattern.findall(body)) == 1, name
        assert re.search(r"^The CPU time \(\d+ s[^)]*\) depends on the machine; every other number here does not",
                         body, re.M), name
        masked = report.comparable(name, body)
        assert masked != body.rstrip()
        assert masked.replace("…", pattern.findall(body)[0]) == body.rstrip()


def test_check_masks_the_curve_speed_blocks_machine_and_times_only():
    """report.comparable masks the curve_speed block's run record (date, CPUs, load) and its times, each once, and
    nothing else: the points and the residuals are compared."""
    body = report.parse_blocks((ROOT / "docs" / "continuation.md").read_text())["curve_speed"].rstrip()
    masked = report.comparable("curve_speed", body)
    found = report.CURVE_MACHINE.findall(body)
    assert len(found) == 2 and masked.count("…") == 2
    assert re.search(r"\d{4}-\d\d-\d\d \d\d:\d\d UTC, \d+ CPUs, load average", found[0])
    assert re.fullmatch(r"[0-9.]+ s wall clock, [0-9.]+ s CPU \(\d+ ms CPU per point\)", found[1])
    assert masked.replace("…", found[0], 1).replace("…", found[1], 1) == body
    assert re.search(r"a fold curve of \d+ points in .*\|P\(z\) − z\| ≤ \S+, \|det\(M − I\)\| ≤ \S+ over its \d+ points",
                     masked)


def test_check_compares_the_auto_blocks_counts_and_choices_not_its_costs():
    """report.comparable on docs/rungs.md's auto block: a change of any cell of its tables, one at a time, changes
    the compared text exactly when the cell is one --check derives again (report.AUTO_COMPARED: the counts, met,
    refused, compared, auto's choices and auto's own loop cost; not the oracle's columns, the measured costs or
    auto's modelled set-up); a change of the date does not."""
    body = report.parse_blocks((ROOT / "docs" / "rungs.md").read_text())["auto"].rstrip()
    base = report.comparable("auto", body)
    lines, columns, cells_seen = body.splitlines(), None, 0
    for i, line in enumerate(lines):
        if not line.startswith("|"):
            columns = None
            continue
        cells = line.strip().strip("|").split("|")
        if columns is None:  # the header
            columns = report.AUTO_COMPARED[cells[0].strip()]
            costs = cells[0].strip() == "candidate"
            continue
        if set(line) <= set("|-"):
            continue
        for j, cell in enumerate(cells):
            parts = cell.split(",") if costs and j >= 1 else [cell]
            for k in range(len(parts)):
                doctored = [*parts[:k], " 9.87654", *parts[k + 1:]]
                changed = cells[:j] + [",".join(doctored)] + cells[j + 1:]
                text = "\n".join([*lines[:i], "|" + "|".join(changed) + "|", *lines[i + 1:]])
                compared = j in columns and not (costs and (j == 2 or k == 1))
                assert (report.comparable("auto", text) != base) == compared, (line, j, k)
                cells_seen += 1
    assert cells_seen >= 2 * 7 + 8 * 6 + 11 * 5  # the documented campaign's tables: every cell tried
    when = re.search(r"Measured (\S+ \S+ UTC)", body)[1]
    assert report.comparable("auto", body.replace(when, "2031-01-01 00:00 UTC")) == base


def test_the_replayed_auto_campaign_is_the_documented_one():
    """--check replays the campaign (pairs, seed) the auto block reports."""
    from vibrofmu.analyses.error_calibration import DOCUMENTED_AUTO

    block = report.parse_blocks((ROOT / "docs" / "rungs.md").read_text())["auto"]
    assert re.findall(r"error_calibration auto (\d+) (\d+) ", block) == [tuple(map(str, DOCUMENTED_AUTO))]


def test_the_report_runs_the_documented_cascade():
    """The cascade --check and a full report run (report.CASCADE_ARGV) is the command the block names."""
    block = report.parse_blocks((ROOT / "docs" / "continuation.md").read_text())["cascade"]
    assert block.startswith("`vibrofmu continuation " + " ".join(report.CASCADE_ARGV) + "` (")


def test_the_replayed_campaigns_are_the_documented_ones():
    """calibration_replay replays the first scenes of the campaigns the calibration block reports."""
    from vibrofmu.analyses.error_calibration import DOCUMENTED_CAMPAIGNS

    block = report.parse_blocks((ROOT / "docs" / "rungs.md").read_text())["calibration"]
    commands = re.findall(r"error_calibration campaign (\S+) \d+ (\d+) ", block)
    assert sorted((rung, int(seed)) for rung, seed in commands) == sorted(DOCUMENTED_CAMPAIGNS)


# checked by the slow test below: the container (~26 s of FMU runs, three H down to 0.01), the SSP orderings
# (a minute of runs: three orderings at three H) and the oafm block (a full `vibrofmu oafm`: ~50 s of CPU)
SLOW_CHECKS = ("container", "ssp_orderings", "oafm", "calibration_replay",  # (+ the replay: ten seconds, and the
               "cascade", "cusp_order",  # cascade and the cusp study: ~25 s of wall clock on a loaded machine,
               "curve_speed", "auto")  # `bench --curve`: 17 s of CPU, the auto replay: 8 s)


def test_report_check_matches_a_fresh_run(plant_fmu, controller_fmu, closed_loop_fmu, capsys, monkeypatch):
    """The accuracy, SSP, ranges and stability blocks are deterministic on one machine: a fresh run (a full
    `vibrofmu stability` for the last) must print the same text."""
    import vibrofmu.commands.report as command

    monkeypatch.setattr(report, "DETERMINISTIC", tuple(n for n in report.DETERMINISTIC if n not in SLOW_CHECKS))
    monkeypatch.setattr(command, "FROM_CHECKED", tuple(n for n in command.FROM_CHECKED if n not in SLOW_CHECKS))
    assert main(["report", "--check", "--fmu-dir", str(plant_fmu.parent), "--root", str(ROOT)]) == 0, \
        capsys.readouterr().err
    assert "accuracy, ranges, ssp, stability match" in capsys.readouterr().out


@pytest.mark.slow
def test_report_check_of_every_deterministic_block(plant_fmu, controller_fmu, closed_loop_fmu, capsys):
    """`vibrofmu report --check` as a user runs it: every block that does not depend on the machine, the
    container's table and the oafm and stability studies' blocks too."""
    assert main(["report", "--check", "--fmu-dir", str(plant_fmu.parent), "--root", str(ROOT)]) == 0, \
        capsys.readouterr().err
    assert ("accuracy, auto, calibration_replay, cascade, container, curve_speed, cusp_order, oafm, ranges, ssp, "
            "ssp_orderings, stability match" in capsys.readouterr().out)


@pytest.mark.slow
def test_report_check_recomputes_the_cascade_and_the_cusp_study(capsys, monkeypatch):
    """`report --check`'s own runs of the documented cascade (`vibrofmu continuation`) and of the cusp study give
    the published blocks, every number but the CPU times (no FMU; measured 7 s of CPU for the continuation with
    its plots, 5 s for the cusp study)."""
    import vibrofmu.commands.report as command

    monkeypatch.setattr(report, "DETERMINISTIC", ())
    monkeypatch.setattr(command, "FROM_CHECKED", ("cascade", "cusp_order"))
    assert main(["report", "--check", "--root", str(ROOT)]) == 0, capsys.readouterr().err
    assert "blocks cascade, cusp_order match a fresh run" in capsys.readouterr().out


@pytest.mark.slow
def test_report_check_recomputes_the_curve_and_the_auto_choices(capsys, monkeypatch):
    """`report --check`'s own `vibrofmu bench --curve` and replay of the documented auto campaign give the published
    curve_speed and auto blocks, every number but the timings (no FMU; measured 17 s of CPU for the curve with its
    check of every point, 8 s for the replay of 500 pairs)."""
    import vibrofmu.commands.report as command

    monkeypatch.setattr(report, "DETERMINISTIC", ())
    monkeypatch.setattr(command, "FROM_CHECKED", ("curve_speed", "auto"))
    assert main(["report", "--check", "--root", str(ROOT)]) == 0, capsys.readouterr().err
    assert "blocks auto, curve_speed match a fresh run" in capsys.readouterr().out
