"""Results on disk: DIR/results.parquet (compacted) plus DIR/parts/*.parquet (one file per finished batch).

Every file is written whole to a temporary name and renamed (os.replace is atomic on POSIX), so at any
moment — Ctrl-C, a killed client, a full disk — every .parquet file in DIR is complete and readable, and
a case is either entirely on disk (all its rows) or not at all. `load` reads both places and is what
--resume uses to skip the cases already written; `compact` folds the parts into results.parquet.
Rows are identified by (case, point): `point` numbers the rows of a case (the frequencies of one
response-map sweep; 0 for the other kinds).
"""
from __future__ import annotations

import json
import os
import uuid
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

RESULTS = "results.parquet"
PARTS = "parts"
SPEC = "spec.json"


def _write_atomic(table: pa.Table, path: Path) -> None:
    tmp = path.with_name(f".{path.name}.{uuid.uuid4().hex}.tmp")
    pq.write_table(table, tmp)
    os.replace(tmp, path)


class Store:
    def __init__(self, out_dir: Path):
        self.dir = Path(out_dir)
        self.parts = self.dir / PARTS
        self.written: set[int] = set()  # case ids on disk

    def prepare(self, spec_record: dict, resume: bool) -> None:
        """Create DIR; with resume, check that DIR holds this study (same spec digest); without, refuse a DIR
        that already holds results (so that nothing is overwritten by accident)."""
        from vibrofmu.study.spec import SpecError

        self.dir.mkdir(parents=True, exist_ok=True)
        self.parts.mkdir(exist_ok=True)
        spec_path = self.dir / SPEC
        has_results = (self.dir / RESULTS).exists() or any(self.parts.glob("*.parquet"))
        if resume and spec_path.exists():
            previous = json.loads(spec_path.read_text())
            if previous.get("digest") != spec_record["digest"]:
                raise SpecError(f"--resume: {self.dir} holds another study (spec digest {previous.get('digest')}, "
                                f"this one {spec_record['digest']}); use another --out")
        elif has_results and not resume:
            raise SpecError(f"{self.dir} already holds results: add --resume to continue that study, or use another --out")
        tmp = spec_path.with_name(f".{SPEC}.tmp")
        tmp.write_text(json.dumps(spec_record, indent=2))
        os.replace(tmp, spec_path)
        self.written = set(self.load_cases())

    def files(self) -> list[Path]:
        results = self.dir / RESULTS
        return ([results] if results.exists() else []) + sorted(self.parts.glob("*.parquet"))

    def load(self) -> pa.Table | None:
        """Every row on disk, duplicates (a case in two files) dropped, by (case, point)."""
        tables = [pq.read_table(path) for path in self.files()]
        if not tables:
            return None
        table = pa.concat_tables(tables, promote_options="permissive")
        table = table.sort_by([("case", "ascending"), ("point", "ascending")])
        keys = list(zip(table.column("case").to_pylist(), table.column("point").to_pylist()))
        keep = [i for i, key in enumerate(keys) if i == 0 or key != keys[i - 1]]
        return table.take(keep) if len(keep) != len(keys) else table

    def load_cases(self) -> list[int]:
        cases = set()
        for path in self.files():
            cases.update(pq.read_table(path, columns=["case"]).column("case").to_pylist())
        return sorted(cases)

    def write(self, rows: list[dict]) -> int:
        """Write the rows of finished cases not yet on disk (one part file); returns how many cases."""
        rows = [row for row in rows if row["case"] not in self.written]
        if not rows:
            return 0
        cases = {row["case"] for row in rows}
        _write_atomic(pa.Table.from_pylist(rows), self.parts / f"part-{min(cases):07d}-{uuid.uuid4().hex[:8]}.parquet")
        self.written |= cases
        return len(cases)

    def compact(self) -> pa.Table | None:
        """Fold the part files into results.parquet (written whole, then the parts removed)."""
        parts = sorted(self.parts.glob("*.parquet"))
        table = self.load()
        if table is None or not parts:
            return table
        _write_atomic(table, self.dir / RESULTS)
        for path in parts:
            path.unlink()
        return table
