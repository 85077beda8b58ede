"""Results on disk: DIR/results.parquet (compacted) plus DIR/parts/*.parquet (one file per finished batch).

Every file is written whole to a temporary name and renamed (os.replace is atomic on POSIX), so at any
moment — Ctrl-C, a killed client, a full disk — every .parquet file in DIR is complete and readable, and
a case is either entirely on disk (all its rows) or not at all. `load` reads both places and is what
--resume uses to skip the cases already written; `compact` folds the parts into results.parquet.
Rows are identified by (case, point): `point` numbers the rows of a case (the frequencies of one
response-map sweep; 0 for the other kinds).

Files are never trusted blindly (issue 26): every Parquet file is written with page checksums (CRC-32 of each
data page) and read with their verification, and carries in its key-value metadata the study's spec digest
and a SHA-256 of its rows (rows_digest). Reading checks all three; a file that fails (unreadable, truncated,
a flipped byte, another study's) is named in one line on stderr and set aside -- renamed to NAME.corrupt, not
deleted -- and its cases count as not computed: `--resume` recomputes them.
"""
from __future__ import annotations

import hashlib
import json
import os
import sys
import uuid
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

RESULTS = "results.parquet"
PARTS = "parts"
SPEC = "spec.json"
SPEC_KEY, ROWS_KEY = b"vibrofmu_spec_digest", b"vibrofmu_rows_digest"  # the key-value metadata of every file
SET_ASIDE = ".corrupt"  # suffix of a file set aside


def rows_digest(table: pa.Table) -> str:
    """SHA-256 of the rows: every column's name, type and values (floats by repr: exact), in column order."""
    digest = hashlib.sha256()
    for name in table.column_names:
        column = table.column(name)
        digest.update(json.dumps([name, str(column.type), column.to_pylist()], default=repr).encode())
    return digest.hexdigest()


def write_atomic(table: pa.Table, path: Path, spec_digest: str) -> None:
    table = table.replace_schema_metadata({SPEC_KEY: spec_digest.encode(), ROWS_KEY: rows_digest(table).encode()})
    tmp = path.with_name(f".{path.name}.{uuid.uuid4().hex}.tmp")
    try:
        pq.write_table(table, tmp, write_page_checksum=True)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


class CorruptFile(Exception):
    """A stored file that fails its checks."""


def read_checked(path: Path, spec_digest: str | None) -> pa.Table:
    """The rows of `path` after every check: page checksums, the spec digest (None: not checked) and the rows'
    digest; CorruptFile saying which failed."""
    try:
        return _checked(pq.read_table(path, page_checksum_verification=True), spec_digest)
    except CorruptFile:
        raise
    except Exception as error:  # pyarrow's errors for a damaged file are of many kinds (OSError, ArrowInvalid,
        # UnicodeDecodeError of damaged metadata, ...)
        first = str(error).splitlines()[0] if str(error) else ""
        raise CorruptFile(f"unreadable ({type(error).__name__}: {first})") from None


def _checked(table: pa.Table, spec_digest: str | None) -> pa.Table:
    metadata = table.schema.metadata or {}
    if SPEC_KEY not in metadata or ROWS_KEY not in metadata:
        raise CorruptFile("no vibrofmu digests in its metadata")
    if spec_digest is not None and metadata[SPEC_KEY].decode(errors="replace") != spec_digest:
        raise CorruptFile(f"written for another study (spec digest {metadata[SPEC_KEY].decode(errors='replace')!r}, "
                          f"this one {spec_digest})")
    table = table.replace_schema_metadata(None)
    if rows_digest(table) != metadata[ROWS_KEY].decode(errors="replace"):
        raise CorruptFile("its rows differ from their digest")
    return table


class Store:
    def __init__(self, out_dir: Path):
        self.dir = Path(out_dir)
        self.parts = self.dir / PARTS
        self.written: set[int] = set()  # case ids on disk
        self.digest: str | None = None  # the study's spec digest (prepare)
        self.set_aside: list[Path] = []  # files found corrupt and renamed

    def prepare(self, spec_record: dict, resume: bool) -> None:
        """Create DIR; with resume, check that DIR holds this study (same spec digest); without, refuse a DIR
        that already holds results (so that nothing is overwritten by accident)."""
        from vibrofmu.study.spec import Spec, SpecError

        self.dir.mkdir(parents=True, exist_ok=True)
        self.parts.mkdir(exist_ok=True)
        spec_path = self.dir / SPEC
        has_results = (self.dir / RESULTS).exists() or any(self.parts.glob("*.parquet"))
        self.digest = spec_record["digest"]
        previous = None
        if resume and spec_path.exists():
            try:
                previous = json.loads(spec_path.read_text())
                if not isinstance(previous, dict):
                    raise ValueError("not a JSON object")
                if previous.get("digest") != Spec(**previous["spec"]).digest():
                    raise ValueError("its digest is not that of its spec")
            except Exception as error:  # damaged (each Parquet file carries the digest too): set aside
                self._set_aside(spec_path, f"unreadable ({type(error).__name__}: {error})")
                previous = None
        if previous is not None:
            if previous.get("digest") != spec_record["digest"]:
                raise SpecError(f"--resume: {self.dir} holds another study (spec digest {previous.get('digest')}, "
                                f"this one {spec_record['digest']}); use another --out")
        elif has_results and not resume:
            raise SpecError(f"{self.dir} already holds results: add --resume to continue that study, or use another --out")
        tmp = spec_path.with_name(f".{SPEC}.tmp")
        tmp.write_text(json.dumps(spec_record, indent=2))
        os.replace(tmp, spec_path)
        self.written = set(self.load_cases())

    def discard(self) -> None:
        """Remove what prepare wrote into a folder it made (spec.json, the empty parts/, the folder): a study that
        cannot start leaves nothing behind."""
        (self.dir / SPEC).unlink(missing_ok=True)
        for folder in (self.parts, self.dir):
            try:
                folder.rmdir()  # only an empty folder goes
            except OSError:
                pass

    def files(self) -> list[Path]:
        results = self.dir / RESULTS
        return ([results] if results.exists() else []) + sorted(self.parts.glob("*.parquet"))

    def _set_aside(self, path: Path, reason: str) -> None:
        """Rename a damaged file to NAME.corrupt (a free name) and say so in one line: a results file's cases are
        recomputed; spec.json is written anew (every results file carries the spec digest it was written for)."""
        target = path.with_name(path.name + SET_ASIDE)
        k = 1
        while target.exists():
            k += 1
            target = path.with_name(f"{path.name}{SET_ASIDE}{k}")
        os.replace(path, target)
        self.set_aside.append(target)
        then = ("this study's spec is written in its place (each results file is checked against it)"
                if path.name == SPEC else "its cases are recomputed (--resume)")
        print(f"warning: {path} is damaged: {reason}; set aside as {target.name}, {then}", file=sys.stderr)

    def tables(self) -> list[pa.Table]:
        """The rows of every stored file that passes read_checked; the others are set aside."""
        tables = []
        for path in self.files():
            try:
                tables.append(read_checked(path, self.digest))
            except CorruptFile as error:
                self._set_aside(path, f"{error}")
        return tables

    def load(self) -> pa.Table | None:
        """Every row on disk, duplicates (a case in two files) dropped, by (case, point)."""
        tables = self.tables()
        if not tables:
            return None
        table = pa.concat_tables(tables, promote_options="permissive")
        table = table.sort_by([("case", "ascending"), ("point", "ascending")])
        keys = list(zip(table.column("case").to_pylist(), table.column("point").to_pylist()))
        keep = [i for i, key in enumerate(keys) if i == 0 or key != keys[i - 1]]
        return table.take(keep) if len(keep) != len(keys) else table

    def load_cases(self) -> list[int]:
        cases = set()
        for table in self.tables():
            cases.update(table.column("case").to_pylist())
        return sorted(cases)

    def write(self, rows: list[dict]) -> int:
        """Write the rows of finished cases not yet on disk (one part file); returns how many cases."""
        rows = [row for row in rows if row["case"] not in self.written]
        if not rows:
            return 0
        cases = {row["case"] for row in rows}
        write_atomic(pa.Table.from_pylist(rows), self.parts / f"part-{min(cases):07d}-{uuid.uuid4().hex[:8]}.parquet",
                      self.digest)
        self.written |= cases
        return len(cases)

    def compact(self) -> pa.Table | None:
        """Fold the part files into results.parquet (written whole, then the parts removed)."""
        parts = sorted(self.parts.glob("*.parquet"))
        table = self.load()
        if table is None or not parts:
            return table
        write_atomic(table, self.dir / RESULTS, self.digest)
        for path in parts:
            if path.exists():  # (not one set aside meanwhile)
                path.unlink()
        return table
