"""Atomic file output: write to a temporary file beside the target, then rename.

Policy (the same for every file photogeom writes):

* Readers of the destination see either the old file or the complete new one, never a
  partial file. The data are fsynced before the rename and the directory after it.
* A new file gets the mode a plain ``open(path, "w")`` would give it: ``0666`` minus the
  umask, applied by the operating system when the temporary file is created (the umask is
  never read or changed, so other threads are not affected). A replaced file keeps its mode,
  and its owner and group as far as this user may set them (see :func:`_take_over`), as a
  plain ``open()`` rewriting it in place would.
* A destination that is a **symbolic link** is followed: the file it points to is replaced
  and the link stays, as a plain ``open()`` would do.
* A destination that exists but may not be written (no write permission bit, or not
  writable by this user) is **refused**, as a plain ``open()`` would refuse it: a rename
  would otherwise replace a file its owner protected.
* A destination that is a directory, or in a directory that does not exist, is refused.
* A destination that is a **character device or a named pipe** (``/dev/null``,
  ``/dev/stdout``, a FIFO) is written in place, as a plain ``open()`` writes it (a rename
  would put a regular file where the device or the pipe was); with several files, after the
  regular files are in place. A block device or a socket is refused.
* Every failure (permissions, disk full, file-size limit, ...) raises
  :class:`~photogeom.errors.OutputError` naming the file and the cause; the temporary files
  are removed and the destinations are left as they were.
* :func:`atomic_write_many` writes several files as one: when any of them cannot be written,
  none is changed.
* The temporary file is named ``.<name>.<random>.tmp``, with ``<name>`` shortened when needed
  so that the name fits the file system's limit (255 bytes on most): any destination name
  that a plain ``open()`` accepts is accepted.
"""

from __future__ import annotations

import errno
import os
import secrets
import shutil
import stat
from collections.abc import Sequence
from pathlib import Path

from .errors import InputError, OutputError

_HINTS = {
    errno.EACCES: "permission denied; choose a writable location",
    errno.EPERM: "operation not permitted; choose a writable location",
    errno.EROFS: "the file system is read-only; choose a writable location",
    errno.ENOSPC: "no space left on the device; free some space or write elsewhere",
    errno.EDQUOT: "disk quota exceeded; free some space or write elsewhere",
    errno.EFBIG: "file too large for the file-size limit (ulimit -f) or the file system",
    errno.EISDIR: "it is a directory; give a file name",
    errno.ENOTDIR: "a part of the path is not a directory",
    errno.ENAMETOOLONG: "the file name is too long",
}


#: Longest file name (bytes) assumed where the file system does not say (ext4, XFS, APFS, ...).
_NAME_MAX = 255


#: Bytes of the random part of a temporary file's name (twice as many hexadecimal digits).
_RANDOM_BYTES = 6


def remove_temporaries(path: str | os.PathLike) -> None:
    """Remove the temporary files that atomic writes of ``path`` left behind in a process
    that ended before renaming or removing them (killed for memory, a crash).

    Parameters
    ----------
    path : str or os.PathLike
        The destination of the writes; its own file is not touched.
    """
    from glob import escape

    target = Path(path)
    tail = "." + "0" * (2 * _RANDOM_BYTES) + ".tmp"
    head = _temporary_name(target.parent, target.name, tail).name[: -len(tail)]
    pattern = escape(head) + "." + "[0-9a-f]" * (2 * _RANDOM_BYTES) + ".tmp"
    for p in target.parent.glob(pattern):
        try:
            p.unlink()
        except OSError:  # gone meanwhile, or not ours to remove
            pass


def _temporary_name(directory: Path, name: str, tail: str) -> Path:
    """``directory / ("." + name + tail)``, ``name`` cut so that the file name fits the
    directory's file-name limit in bytes.

    Parameters
    ----------
    directory : Path
        Where the temporary file or folder is made (beside its destination).
    name : str
        The destination's file name.
    tail : str
        What follows it, e.g. ``".<random>.tmp"`` (kept whole).

    Returns
    -------
    Path
        A name no longer than the limit, so that a destination name of up to the limit does
        not fail as too long only because of its temporary name.
    """
    try:
        limit = int(os.pathconf(directory, "PC_NAME_MAX"))
    except (AttributeError, OSError, ValueError):  # no pathconf (Windows), or no answer
        limit = _NAME_MAX
    if limit <= 0:
        limit = _NAME_MAX
    room = max(1, limit - 1 - len(os.fsencode(tail)))
    raw = os.fsencode(name)
    if len(raw) > room:
        cut = raw[:room]
        # whole UTF-8 characters only: drop a multi-byte sequence cut in the middle
        while cut and (cut[-1] & 0xC0) == 0x80:
            cut = cut[:-1]
        if cut and cut[-1] >= 0xC0:
            cut = cut[:-1]
        name = os.fsdecode(cut)
    return directory / f".{name}{tail}"


def _create_temporary(given: Path, target: Path) -> tuple[int, Path, os.stat_result | None]:
    """Create a new temporary file beside ``target`` (``O_EXCL``, mode 0666 minus the umask,
    as ``open(path, "w")``; the name by :func:`_temporary_name`).

    Parameters
    ----------
    given : Path
        The destination as the user named it (for messages).
    target : Path
        The destination with symbolic links resolved (:func:`_destination`).

    Returns
    -------
    fd : int
        The open file descriptor (write only).
    tmp : Path
        The temporary file's path.
    old : os.stat_result or None
        The status of the file ``target`` will replace (for :func:`_take_over`); None when
        there is none.

    Raises
    ------
    OutputError
        Naming ``given``, when the destination or the folder cannot be used.
    """
    directory = target.parent if str(target.parent) else Path(".")
    try:
        old = target.stat()
    except FileNotFoundError:
        old = None
    except OSError as exc:
        raise _failure(given, exc) from exc
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0)
    for _ in range(100):
        tmp = _temporary_name(directory, target.name, f".{secrets.token_hex(_RANDOM_BYTES)}.tmp")
        try:
            # 0o666: the kernel applies the umask, exactly as for open(path, "w")
            return os.open(tmp, flags, 0o666), tmp, old
        except FileExistsError:
            continue
        except OSError as exc:
            raise _failure(given, exc) from exc
    raise OutputError(  # pragma: no cover - 100 collisions of 48 random bits
        f"cannot write {given}: no free temporary file name"
    )


def _take_over(fd: int, old: os.stat_result | None) -> None:
    """Give the new file ``fd`` the owner, group and mode of the file it replaces.

    A plain ``open()`` rewrites a file in place and keeps all three; a renamed temporary
    file would otherwise belong to this user and primary group (a file of a shared project
    group would lose its group, a file rewritten with ``sudo`` would become root's). The
    owner is kept where this user may set it (root, or the owner itself), the group where
    this user belongs to it; the mode always.

    Parameters
    ----------
    fd : int
        The temporary file, open for writing.
    old : os.stat_result or None
        The destination's status; None for a new file (which keeps ``0666`` minus umask).
    """
    if old is None:
        return
    now = os.fstat(fd)
    if hasattr(os, "fchown"):
        if (now.st_uid, now.st_gid) != (old.st_uid, old.st_gid):
            for uid in (old.st_uid, -1):  # owner and group, else the group alone
                try:
                    os.fchown(fd, uid, old.st_gid)
                    break
                except OSError:  # not permitted (or not supported by the file system)
                    continue
    mode = stat.S_IMODE(old.st_mode)
    # only a change: file systems with fixed modes (FAT, exFAT) refuse any chmod (EPERM);
    # after fchown, which may clear the set-id bits
    if hasattr(os, "fchmod") and stat.S_IMODE(os.fstat(fd).st_mode) != mode:
        os.fchmod(fd, mode)


def _failure(target: Path, exc: OSError) -> OutputError:
    reason = _HINTS.get(exc.errno) if exc.errno is not None else None
    if reason is None:
        reason = exc.strerror or str(exc) or type(exc).__name__
    return OutputError(f"cannot write {target}: {reason}", exc.errno)


def _stream(path: Path) -> bool:
    """``path`` is (or links to) a character device or a named pipe: ``/dev/null``,
    ``/dev/stdout``, a FIFO. Such a destination is written in place, as a plain ``open()``
    writes it: it cannot be replaced by a renamed file (that would put a regular file where
    the device or the pipe was)."""
    try:
        mode = os.stat(path).st_mode
    except (OSError, ValueError):
        return False
    return stat.S_ISCHR(mode) or stat.S_ISFIFO(mode)


def _write_stream(given: Path, data: bytes) -> None:
    """Write ``data`` into the device or named pipe ``given`` (see :func:`_stream`)."""
    try:
        with open(given, "wb") as fh:
            fh.write(data)
    except OSError as exc:
        raise _failure(given, exc) from exc


def _destination(path: str | os.PathLike) -> tuple[Path, Path]:
    """(name as given, real file to replace): symbolic links are followed. A device or a
    named pipe (:func:`_stream`) is returned as given; a block device or a socket is
    refused."""
    given = Path(os.fspath(path))
    if not given.name:
        raise OutputError(f"cannot write {given}: give a file name, not a directory")
    try:
        mode = os.stat(given).st_mode
    except (OSError, ValueError):
        mode = None
    if mode is not None and not (stat.S_ISREG(mode) or stat.S_ISDIR(mode)):
        if stat.S_ISCHR(mode) or stat.S_ISFIFO(mode):
            if not os.access(given, os.W_OK):
                raise OutputError(
                    f"cannot write {given}: permission denied; choose a writable location"
                )
            return given, given
        kind = "a block device" if stat.S_ISBLK(mode) else "a socket or special file"
        raise OutputError(f"cannot write {given}: it is {kind}, not a file; give a file name")
    target = Path(os.path.realpath(given)) if given.is_symlink() else given
    directory = target.parent if str(target.parent) else Path(".")
    if not directory.is_dir():
        raise OutputError(
            f"cannot write {given}: directory {directory} does not exist; create it first"
        )
    if target.is_dir():
        raise OutputError(f"cannot write {given}: it is a directory; give a file name")
    if target.exists():
        mode = target.stat().st_mode
        if not (mode & 0o222) or not os.access(target, os.W_OK):
            raise OutputError(
                f"cannot write {given}: the existing file is read-only; make it writable "
                "(chmod u+w) or choose another output file"
            )
    return given, target


class _Staged:
    """One file written to a temporary name beside its destination, not yet renamed."""

    def __init__(self, given: Path, target: Path, data: bytes) -> None:
        self.given = given
        self.target = target
        self.tmp: Path | None = None
        self.backup: Path | None = None
        fd, tmp, old = _create_temporary(given, target)
        self.tmp = tmp
        try:
            with os.fdopen(fd, "wb") as fh:
                _take_over(fh.fileno(), old)
                fh.write(data)
                fh.flush()
                os.fsync(fh.fileno())
        except OSError as exc:
            self.discard()
            raise _failure(given, exc) from exc
        except BaseException:
            self.discard()
            raise

    def keep_old(self) -> None:
        """Hard-link the current destination (if any) to a backup name, for a rollback."""
        if not self.target.exists():
            return
        backup = self.tmp.with_name(self.tmp.name[:-4] + ".old")
        try:
            os.link(self.target, backup)
        except OSError:
            # a file system without hard links: keep a copy instead
            try:
                shutil.copy2(self.target, backup)
            except OSError as exc:
                try:
                    os.unlink(backup)
                except OSError:
                    pass
                raise _failure(self.given, exc) from exc
        self.backup = backup

    def discard(self) -> None:
        for p in (self.tmp, self.backup):
            if p is not None:
                try:
                    os.unlink(p)
                except FileNotFoundError:
                    pass
        self.tmp = self.backup = None


def _fsync_directory(directory: Path) -> None:
    """Make a rename in ``directory`` durable (POSIX; a no-op where directories cannot be
    opened, e.g. Windows)."""
    flags = os.O_RDONLY | getattr(os, "O_DIRECTORY", 0)
    try:
        fd = os.open(directory, flags)
    except OSError:  # pragma: no cover - platforms without directory handles
        return
    try:
        os.fsync(fd)
    except OSError as exc:  # pragma: no cover - file systems that cannot sync directories
        if exc.errno not in (errno.EINVAL, errno.ENOTSUP, errno.EBADF):
            raise
    finally:
        os.close(fd)


def atomic_write_many(items: Sequence[tuple[str | os.PathLike, bytes]]) -> list[Path]:
    """Write several files as one: either all are replaced, or none is changed.

    Every file is first written in full to a temporary file beside its destination; only
    when all are written are they renamed into place. Should a rename fail, the files
    already renamed are put back as they were.

    Parameters
    ----------
    items : sequence of (path, bytes)
        Destinations and their contents. A destination may appear only once.

    Returns
    -------
    list of Path
        The destinations, as given.

    Raises
    ------
    OutputError
        A destination cannot be written (see the module's policy); nothing was changed.
    InputError
        The same destination given twice.
    """
    prepared = []
    for p, data in items:
        try:
            prepared.append((_destination(p), data))
        except OSError as exc:
            if isinstance(exc, OutputError):
                raise
            raise _failure(Path(os.fspath(p)), exc) from exc
    seen: dict[str, Path] = {}
    for (given, target), _ in prepared:
        key = os.path.normcase(os.path.abspath(target))
        if key in seen:
            raise InputError(f"{given} and {seen[key]} are the same file: give different outputs")
        seen[key] = given
    streams = [(given, data) for (given, target), data in prepared if _stream(target)]
    prepared_files = [item for item in prepared if not _stream(item[0][1])]
    staged: list[_Staged] = []
    try:
        for (given, target), data in prepared_files:
            staged.append(_Staged(given, target, data))
        if len(staged) > 1:
            for s in staged:
                s.keep_old()
        done: list[_Staged] = []
        try:
            for s in staged:
                try:
                    os.replace(s.tmp, s.target)
                except OSError as exc:
                    raise _failure(s.given, exc) from exc
                s.tmp = None
                done.append(s)
        except BaseException:
            for s in reversed(done):  # roll back: old contents back, new files removed
                try:
                    if s.backup is not None:
                        os.replace(s.backup, s.target)
                        s.backup = None
                    else:
                        os.unlink(s.target)
                except OSError:  # pragma: no cover - the directory vanished meanwhile
                    pass
            raise
        for directory in {s.target.parent for s in staged}:
            try:
                _fsync_directory(directory if str(directory) else Path("."))
            except OSError as exc:  # pragma: no cover - I/O error on the directory
                raise _failure(directory, exc) from exc
    finally:
        for s in staged:
            s.discard()
    for given, data in streams:  # devices and pipes last: they cannot be rolled back
        _write_stream(given, data)
    return [given for (given, _), _ in prepared]


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` so that readers see either the old or the complete new file.

    The data go to a temporary file in the same directory, are flushed and fsynced, and the
    temporary file is renamed over ``path``; the directory is fsynced after the rename. On
    any error the temporary file is removed and ``path`` is left as it was. See the module
    docstring for symbolic links, read-only files and permissions.

    Parameters
    ----------
    path : str or os.PathLike
        The file to write or replace.
    data : bytes
        The complete new content.

    Returns
    -------
    pathlib.Path
        The path written.

    Raises
    ------
    OutputError
        The file cannot be written (read-only, a directory, missing directory, disk full, ...).
    """
    return atomic_write_many([(path, data)])[0]


def atomic_write_text(path: str | os.PathLike, text: str, encoding: str = "utf-8") -> Path:
    """Text version of :func:`atomic_write_bytes`.

    Parameters
    ----------
    path : str or os.PathLike
        The file to write or replace.
    text : str
        The complete new content.
    encoding : str, default "utf-8"
        Encoding of the file.

    Returns
    -------
    pathlib.Path
        The path written.

    Raises
    ------
    OutputError
        As :func:`atomic_write_bytes`.
    """
    return atomic_write_bytes(path, text.encode(encoding))


def atomic_write_texts(
    items: Sequence[tuple[str | os.PathLike, str]], encoding: str = "utf-8"
) -> list[Path]:
    """Text version of :func:`atomic_write_many`: all files or none.

    Parameters
    ----------
    items : sequence of (path, str)
        Each file's path and its text.
    encoding : str
        The encoding of every text.

    Returns
    -------
    list of pathlib.Path
        The paths written, in the order of ``items``.

    Raises
    ------
    OutputError
        A file that cannot be written; none of the files is then replaced.
    """
    return atomic_write_many([(p, t.encode(encoding)) for p, t in items])
