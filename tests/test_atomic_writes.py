"""Atomic output files: permissions without touching the umask, durability (fsync of the
directory), symbolic links, read-only destinations, failures, several files as one."""

from __future__ import annotations

import os
import stat

import pytest

from photogeom.atomicfile import atomic_write_many, atomic_write_text
from photogeom.errors import InputError, OutputError, PhotogeomError

posix = pytest.mark.skipif(os.name != "posix", reason="POSIX file semantics")


def _names(d):
    return sorted(p.name for p in d.iterdir())


@posix
def test_new_file_mode_comes_from_the_umask_without_reading_it(tmp_path, monkeypatch):
    mask = os.umask(0o027)  # this test sets a distinctive umask for the process ...
    try:

        def forbidden(*_):  # ... and photogeom must never call os.umask itself
            raise AssertionError("os.umask called")

        monkeypatch.setattr(os, "umask", forbidden)
        p = atomic_write_text(tmp_path / "new.txt", "a")
        assert p.stat().st_mode & 0o777 == 0o640
        p.chmod(0o600)
        atomic_write_text(p, "b")
        assert p.stat().st_mode & 0o777 == 0o600  # the replaced file's mode is kept
    finally:
        monkeypatch.undo()
        os.umask(mask)


@posix
def test_directory_is_fsynced_after_the_rename(tmp_path, monkeypatch):
    events = []
    real_fsync, real_replace = os.fsync, os.replace

    def fsync(fd):
        events.append("fsync-dir" if stat.S_ISDIR(os.fstat(fd).st_mode) else "fsync-file")
        return real_fsync(fd)

    def replace(a, b):
        events.append("rename")
        return real_replace(a, b)

    monkeypatch.setattr(os, "fsync", fsync)
    monkeypatch.setattr(os, "replace", replace)
    atomic_write_text(tmp_path / "x.txt", "data")
    assert events == ["fsync-file", "rename", "fsync-dir"]


@posix
def test_symbolic_link_is_followed_and_kept(tmp_path):
    real = tmp_path / "data" / "real.txt"
    real.parent.mkdir()
    real.write_text("old")
    link = tmp_path / "link.txt"
    link.symlink_to(real)
    atomic_write_text(link, "new")
    assert link.is_symlink() and os.readlink(link) == str(real)
    assert real.read_text() == "new"
    assert _names(real.parent) == ["real.txt"] and _names(tmp_path) == ["data", "link.txt"]
    dangling = tmp_path / "dangling.txt"
    dangling.symlink_to(tmp_path / "data" / "created.txt")
    atomic_write_text(dangling, "made")  # as open(): the file the link names is created
    assert (tmp_path / "data" / "created.txt").read_text() == "made" and dangling.is_symlink()


@posix
def test_read_only_destination_is_refused_and_kept(tmp_path):
    p = tmp_path / "ro.txt"
    p.write_text("protected")
    p.chmod(0o444)
    with pytest.raises(OutputError, match=r"read-only.*chmod u\+w"):
        atomic_write_text(p, "x")
    assert p.read_text() == "protected" and _names(tmp_path) == ["ro.txt"]


@pytest.mark.parametrize("kind", ["directory", "missing-directory", "below-a-file", "long-name"])
def test_impossible_destinations_raise_output_error(tmp_path, kind):
    if kind == "directory":
        (tmp_path / "d").mkdir()
        target, words = tmp_path / "d", "directory"
    elif kind == "missing-directory":
        target, words = tmp_path / "nope" / "x.txt", "does not exist"
    elif kind == "below-a-file":
        (tmp_path / "f").write_text("")
        target, words = tmp_path / "f" / "x.txt", "does not exist"
    else:
        target, words = tmp_path / ("n" * 300), "too long"
    with pytest.raises(OutputError, match=words) as info:
        atomic_write_text(target, "x")
    assert isinstance(info.value, OSError) and isinstance(info.value, PhotogeomError)
    assert str(target) in str(info.value)


def test_disk_full_leaves_the_old_file_and_no_temporary(tmp_path, monkeypatch):
    import errno

    p = tmp_path / "out.txt"
    p.write_text("old")
    real_fsync = os.fsync

    def full(fd):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "fsync", full)
    with pytest.raises(OutputError, match="no space left") as info:
        atomic_write_text(p, "new")
    assert info.value.errno == errno.ENOSPC
    monkeypatch.setattr(os, "fsync", real_fsync)
    assert p.read_text() == "old" and _names(tmp_path) == ["out.txt"]


def test_several_files_all_or_nothing_when_one_cannot_be_staged(tmp_path):
    a, b = tmp_path / "a.txt", tmp_path / "b"
    a.write_text("old a")
    b.mkdir()
    with pytest.raises(OutputError, match="directory"):
        atomic_write_many([(a, b"new a"), (b, b"new b")])
    assert a.read_text() == "old a" and _names(tmp_path) == ["a.txt", "b"]


def test_several_files_roll_back_when_a_rename_fails(tmp_path, monkeypatch):
    a, b, c = tmp_path / "a.txt", tmp_path / "b.txt", tmp_path / "c.txt"
    a.write_text("old a")
    c.write_text("old c")
    calls = []
    real_replace = os.replace

    def replace(src, dst):
        calls.append(dst)
        if len(calls) == 3:  # the third rename fails: a and b are already in place
            raise OSError(5, "Input/output error")
        return real_replace(src, dst)

    monkeypatch.setattr(os, "replace", replace)
    with pytest.raises(OutputError, match=r"c\.txt"):
        atomic_write_many([(a, b"new a"), (b, b"new b"), (c, b"new c")])
    monkeypatch.setattr(os, "replace", real_replace)
    assert a.read_text() == "old a" and c.read_text() == "old c" and not b.exists()
    assert _names(tmp_path) == ["a.txt", "c.txt"]


def test_several_files_succeed_together(tmp_path):
    a, b = tmp_path / "a.txt", tmp_path / "sub" / "b.txt"
    b.parent.mkdir()
    a.write_text("old")
    atomic_write_many([(a, b"1"), (b, b"2")])
    assert a.read_text() == "1" and b.read_text() == "2"
    assert _names(tmp_path) == ["a.txt", "sub"] and _names(b.parent) == ["b.txt"]


def test_the_same_file_twice_is_refused(tmp_path):
    with pytest.raises(InputError, match="same file"):
        atomic_write_many([(tmp_path / "a.txt", b"1"), (tmp_path / "." / "a.txt", b"2")])
    assert _names(tmp_path) == []


def test_several_files_without_hard_links_keep_a_copy_for_the_rollback(tmp_path, monkeypatch):
    a, b = tmp_path / "a.txt", tmp_path / "b.txt"
    a.write_text("old a")
    b.write_text("old b")

    def no_links(*_):
        raise OSError(1, "Operation not permitted")

    calls = []
    real_replace = os.replace

    def replace(src, dst):
        calls.append(dst)
        if len(calls) == 2:
            raise OSError(5, "Input/output error")
        return real_replace(src, dst)

    monkeypatch.setattr(os, "link", no_links)
    monkeypatch.setattr(os, "replace", replace)
    with pytest.raises(OutputError):
        atomic_write_many([(a, b"new a"), (b, b"new b")])
    monkeypatch.setattr(os, "replace", real_replace)
    assert a.read_text() == "old a" and b.read_text() == "old b"
    assert _names(tmp_path) == ["a.txt", "b.txt"]
