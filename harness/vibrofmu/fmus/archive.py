"""The entries of an FMU (or any zip the project ships) as a user's unzip expects them: regular files 0644,
folders 0755, made by Unix.

Python's zipfile gives `writestr(name, data)` entries mode 0600 and no file type (external_attr 0o600 << 16),
and pythonfmu's builder writes its own zip the same way; `unzip` then makes files only their owner can read,
and tools that look at the type bits (a file or a folder?) see neither. `normalize_entries` rewrites the archive
once it is complete: every entry keeps its name, bytes, date, compression and order; only its attributes change.

Every archive the project builds (the FMUs, the SSPs, the container FMU) is assembled in a staging folder inside its
destination folder (`staging`) and moved to its final name by `publish` (os.replace: atomic on one file system), so
an interrupted build leaves the previous file or none, never half of one. `finished` tells an archive whose build
ran to its end (normalize_entries is its last step) from one a build of an earlier version left half-done.
`publish` also writes the digest of the sources the archive was built from (`sources_stamp`: fmu_src and the build
code) as the zip's comment; `current` tells an archive of these sources from one an older checkout built, which the
commands rebuild rather than run (an FMU of older sources may not even load against this vibromodel).
"""
from __future__ import annotations

import contextlib
import functools
import hashlib
import os
import shutil
import tempfile
import zipfile
from pathlib import Path

FILE_ATTR = 0o100644 << 16  # S_IFREG | rw-r--r--
DIR_ATTR = (0o40755 << 16) | 0x10  # S_IFDIR | rwxr-xr-x, and MS-DOS's directory bit
UNIX = 3  # ZipInfo.create_system: the high 16 bits of external_attr are a Unix mode


def entry_attributes(info: zipfile.ZipInfo) -> int:
    return DIR_ATTR if info.is_dir() else FILE_ATTR


def normalize_entries(path: Path) -> Path:
    """Rewrite the zip `path` in place with every entry 0644 regular file (0755 folder); returns path."""
    path = Path(path)
    with zipfile.ZipFile(path) as zin:
        infos = zin.infolist()
        if all(i.create_system == UNIX and i.external_attr == entry_attributes(i) for i in infos):
            return path
        fd, tmp = tempfile.mkstemp(suffix=path.suffix, dir=path.parent)
        os.close(fd)
        try:
            with zipfile.ZipFile(tmp, "w") as zout:
                for info in infos:
                    data = zin.read(info)
                    new = zipfile.ZipInfo(info.filename, date_time=info.date_time)
                    new.compress_type = info.compress_type
                    new.create_system = UNIX
                    new.external_attr = entry_attributes(info)
                    new.comment = info.comment
                    zout.writestr(new, data)
            mode = path.stat().st_mode & 0o777
            os.chmod(tmp, mode)
            os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
    return path


def rewrite_members(path: Path, transform, added: tuple = ()) -> None:
    """Rewrite the zip `path` in place, deflated: each member's data through transform(filename, data) (None drops
    the member), then the (filename, data) pairs `added`. A failure leaves `path` as it was."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(suffix=path.suffix, dir=path.parent)
    os.close(fd)
    try:
        with zipfile.ZipFile(path) as zin, zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as zout:
            for info in zin.infolist():
                data = transform(info.filename, zin.read(info.filename))
                if data is not None:
                    zout.writestr(info, data)
            for filename, data in added:
                zout.writestr(filename, data)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


@contextlib.contextmanager
def staging(destination: Path):
    """Yield a fresh hidden folder inside `destination` (created if missing) to assemble archives in; `publish`
    moves each finished one to its final name. The folder and whatever is left in it are removed when the block
    ends, however it ends (an exception, Ctrl-C)."""
    destination = Path(destination)
    destination.mkdir(parents=True, exist_ok=True)
    folder = Path(tempfile.mkdtemp(prefix=".building-", dir=destination))
    try:
        yield folder
    finally:
        shutil.rmtree(folder, ignore_errors=True)


STAMP_PREFIX = b"vibrofmu sources sha256 "
STAMPED_SUFFIXES = (".py", ".c", ".h", ".xml", ".toml", ".json", ".txt")


@functools.lru_cache(maxsize=1)
def sources_stamp() -> bytes:
    """STAMP_PREFIX + the SHA-256 of every source an archive is built from: fmu_src (the model, the C core, the FMI
    layers, the native models) and the build code (this package), each file's path and bytes, in sorted order."""
    from vibrofmu import paths

    digest = hashlib.sha256()
    for root in (paths.FMU_SRC, Path(__file__).resolve().parent):
        for path in sorted(p for p in root.rglob("*") if p.suffix in STAMPED_SUFFIXES and p.is_file()
                           and "__pycache__" not in p.parts):
            digest.update(f"{root.name}/{path.relative_to(root).as_posix()}\0".encode())
            digest.update(path.read_bytes())
            digest.update(b"\0")
    return STAMP_PREFIX + digest.hexdigest().encode()


def stamp(path: Path) -> bytes | None:
    """The zip comment of `path` (its sources_stamp when a build published it), None if it is no readable zip."""
    try:
        with zipfile.ZipFile(path) as archive:
            return archive.comment
    except (OSError, zipfile.BadZipFile):
        return None


def publish(staged: Path, final: Path) -> Path:
    """Write sources_stamp as the finished archive's comment, then move `staged` (in a staging folder of final's
    folder) to `final`, replacing the previous file at once (os.replace); returns final."""
    with zipfile.ZipFile(staged, "a") as archive:
        archive.comment = sources_stamp()
    os.replace(staged, final)
    return Path(final)


def finished(path: Path) -> bool:
    """True when `path` is a readable zip whose every entry has the attributes normalize_entries gives (the last
    step of every build): an archive a build finished, not one an interrupted build of an earlier version left."""
    try:
        with zipfile.ZipFile(path) as archive:
            infos = archive.infolist()
    except (OSError, zipfile.BadZipFile):
        return False
    return bool(infos) and all(i.create_system == UNIX and i.external_attr == entry_attributes(i) for i in infos)


def current(path: Path) -> bool:
    """True when `path` is finished and was built from the sources as they are now (its stamp is sources_stamp)."""
    return finished(path) and stamp(path) == sources_stamp()
