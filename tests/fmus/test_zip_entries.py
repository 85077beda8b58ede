"""Issue 23, item 4: every entry of every FMU (and of the container FMU and the SSP archive) is a regular file,
mode 0644, made by Unix (vibrofmu.fmus.archive.normalize_entries); pythonfmu's builder and zipfile.writestr write
0600 with no file type, which `unzip` turns into files only their owner can read."""
from __future__ import annotations

import stat
import zipfile

import pytest

from vibrofmu.fmus.archive import normalize_entries
from zip_entries import assert_regular_0644, modes

FMUS = ("plant", "controller", "closed_loop", "native_plant", "native_controller", "native_closed_loop")


@pytest.mark.fmu  # asks for its FMU by name (request.getfixturevalue)
@pytest.mark.parametrize("name", FMUS)
def test_every_fmu_entry_is_a_regular_file_0644(name, request):
    assert_regular_0644(request.getfixturevalue(f"{name}_fmu"))


def test_normalize_keeps_names_bytes_order_and_compression(tmp_path):
    """A zip as zipfile.writestr and pythonfmu's builder write it (0600, no type; a folder entry too): after
    normalize_entries the same names in the same order with the same bytes, dates and compression, and the
    modes fixed; a second call leaves the file as it is."""
    path = tmp_path / "a.fmu"
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("modelDescription.xml", b"<fmiModelDescription/>", compress_type=zipfile.ZIP_DEFLATED)
        z.writestr(zipfile.ZipInfo("resources/"), b"")
        z.writestr("resources/data.bin", bytes(range(256)) * 4, compress_type=zipfile.ZIP_STORED)
    path.chmod(0o644)
    before = modes(path)
    assert before["modelDescription.xml"][1] == 0o600 and before["resources/"][1] & 0o170000 == 0
    with zipfile.ZipFile(path) as z:
        old = [(i.filename, i.date_time, i.compress_type, z.read(i)) for i in z.infolist()]
    normalize_entries(path)
    assert_regular_0644(path)
    with zipfile.ZipFile(path) as z:
        assert [(i.filename, i.date_time, i.compress_type, z.read(i)) for i in z.infolist()] == old
        assert z.testzip() is None
    assert stat.S_IMODE(path.stat().st_mode) == 0o644  # the archive's own mode is kept
    written = path.read_bytes()
    normalize_entries(path)
    assert path.read_bytes() == written
