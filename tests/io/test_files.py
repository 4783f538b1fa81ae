"""atomic_write: complete or absent, umask permissions, no overwrite without force (even a late-appearing file)."""

from __future__ import annotations

import os
import stat

import pytest

import gbviewer as gb
from gbviewer.core.files import atomic_write


def test_writes_with_umask_permissions(tmp_path):
    old = os.umask(0o022)
    try:
        out = atomic_write(tmp_path / "a.txt", lambda p: p.write_text("hello"))
    finally:
        os.umask(old)
    assert out.read_text() == "hello"
    assert stat.S_IMODE(out.stat().st_mode) == 0o644
    assert [p.name for p in tmp_path.iterdir()] == ["a.txt"]


def test_refuses_existing_and_late_files(tmp_path):
    target = tmp_path / "b.txt"
    target.write_text("precious")
    with pytest.raises(gb.GBViewerError, match="--force"):
        atomic_write(target, lambda p: p.write_text("new"))
    late = tmp_path / "c.txt"

    def write_while_someone_creates(p):
        p.write_text("new")
        late.write_text("someone else's")

    with pytest.raises(gb.GBViewerError, match="--force"):
        atomic_write(late, write_while_someone_creates)
    assert late.read_text() == "someone else's" and target.read_text() == "precious"
    atomic_write(target, lambda p: p.write_text("new"), force=True)
    assert target.read_text() == "new"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["b.txt", "c.txt"]


def test_failed_write_leaves_nothing(tmp_path):
    def boom(p):
        p.write_text("partial")
        raise RuntimeError("disk on fire")

    with pytest.raises(RuntimeError):
        atomic_write(tmp_path / "d.txt", boom)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.skipif(not hasattr(os, "O_DIRECTORY"), reason="folders are not opened for fsync here (Windows)")
@pytest.mark.parametrize("force", [False, True])
def test_the_folder_is_synced_after_the_file_is_moved_into_it(tmp_path, monkeypatch, force):
    """The file's data is flushed before the rename, the folder's entry after it: a crash after atomic_write returns
    keeps the file."""
    events = []
    fsync, replace, link = os.fsync, os.replace, os.link

    def record(name, fn):
        def call(*args):
            if name == "fsync":
                events.append("fsync folder" if stat.S_ISDIR(os.fstat(args[0]).st_mode) else "fsync file")
            else:
                events.append("move")
            return fn(*args)

        return call

    monkeypatch.setattr(os, "fsync", record("fsync", fsync))
    monkeypatch.setattr(os, "replace", record("replace", replace))
    monkeypatch.setattr(os, "link", record("link", link))
    atomic_write(tmp_path / "out.bin", lambda p: p.write_bytes(b"data"), force=force)
    assert events == ["fsync file", "move", "fsync folder"]
