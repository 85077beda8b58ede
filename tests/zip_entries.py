"""The check of an archive's entries (tests/fmus/test_zip_entries.py, tests/hosts/test_ssp_container.py): every entry
made by Unix, a regular file 0644 (a folder 0755)."""
from __future__ import annotations

import stat
import zipfile


def modes(path) -> dict[str, tuple[int, int]]:
    """name: (create_system, st_mode from external_attr) of each entry."""
    with zipfile.ZipFile(path) as z:
        return {i.filename: (i.create_system, i.external_attr >> 16) for i in z.infolist()}


def assert_regular_0644(path) -> None:
    entries = modes(path)
    assert entries
    for name, (system, mode) in entries.items():
        assert system == 3, f"{path}: {name} is not marked as made by Unix ({system})"
        if name.endswith("/"):
            assert mode == stat.S_IFDIR | 0o755, f"{path}: folder {name} has mode {oct(mode)}"
        else:
            assert mode == stat.S_IFREG | 0o644, f"{path}: {name} has mode {oct(mode)}"
